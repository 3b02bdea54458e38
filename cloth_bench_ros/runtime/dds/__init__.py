"""
The DDS transport of the embedded runtime: Cyclone DDS with rmw_cyclonedds' conventions.

idl.py: the rosidl IDL types; qos.py: QoS; domain.py: the domain and its discovery settings;
cyclone_private.py: the calls below cyclonedds' public API; graph.py: ros_discovery_info
and the node of every endpoint; transport.py: the transport a Context uses.
"""

from cloth_bench_ros.runtime.dds.domain import loopback_environment, LOOPBACK_URI
from cloth_bench_ros.runtime.dds.transport import dds_topic_name, DdsTransport

__all__ = ['LOOPBACK_URI', 'DdsTransport', 'dds_topic_name', 'loopback_environment']
