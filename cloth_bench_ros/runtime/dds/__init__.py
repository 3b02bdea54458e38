"""
The DDS transport of the embedded runtime: Cyclone DDS with rmw_cyclonedds' conventions.

idl.py: the rosidl IDL types; qos.py: QoS; domain.py: the domain and its discovery settings;
cyclone_private.py: the calls below cyclonedds' public API; graph.py: ros_discovery_info
and the node of every endpoint; transport.py: the transport a Context uses.
The package exports only the loopback settings: what starts processes on DDS imports them
without loading Cyclone (0.3 s), which only transport.py and what it imports load.
"""

from cloth_bench_ros.runtime.dds.domain import loopback_environment, LOOPBACK_URI

__all__ = ['LOOPBACK_URI', 'loopback_environment']
