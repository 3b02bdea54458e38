"""
Every node's parameter services over DDS, between OS processes, in rmw_cyclonedds' wire format.

The node is the project's trajectory_publisher started as `python -m` (what its console script
runs), on the loopback DDS domain of conftest.py. One client is the embedded runtime (what a
tool built on it would do); the other writes and reads with Cyclone's own serializer and types
declared here from rcl_interfaces' .srv files plus the 16-byte request header, not the project's
code, so that the layout on the wire is checked independently.
"""

from dataclasses import dataclass, field
import os
import subprocess
import sys
import time

from cloth_bench_ros.runtime import embedded as rclpy
from cloth_bench_ros.runtime.messages import message_class
from cloth_bench_ros.runtime.services import (
    DescribeParameters,
    GetParameters,
    ListParameters,
    SetParameters,
)
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl import types as t
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy, Qos
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
import pytest

NODE = '/cloth_bench/trajectory_publisher'
ParameterMsg = message_class('rcl_interfaces/msg/Parameter')
ParameterValue = message_class('rcl_interfaces/msg/ParameterValue')


@pytest.fixture(scope='module')
def publisher_process():
    """Run the trajectory publisher as its own process over DDS (it waits for simulators)."""
    env = {**os.environ, 'CLOTH_BENCH_EMBEDDED': '1', 'CLOTH_BENCH_TRANSPORT': 'dds'}
    process = subprocess.Popen(
        [sys.executable, '-m', 'cloth_bench_ros.nodes.trajectory_publisher',
         '--ros-args', '-p', 'rate_hz:=250.0'],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    yield process
    process.terminate()
    process.wait(timeout=20)


def _call(executor, node, srv_type, name: str, request):
    client = node.create_client(srv_type, name)
    assert client.wait_for_service(timeout_sec=20.0), f'{name} never became ready'
    future = client.call_async(request)
    executor.spin_until_future_complete(future, timeout_sec=10.0)
    assert future.done(), f'{name}: no answer'
    return future.result()


def test_an_embedded_client_lists_reads_and_is_refused_by_a_node_process(publisher_process):
    context = rclpy.Context()
    rclpy.init(args=[], context=context, transport='dds')
    try:
        node = rclpy.create_node('param_client', context=context)
        executor = rclpy.SingleThreadedExecutor(context)
        executor.add_node(node)
        listed = _call(executor, node, ListParameters, f'{NODE}/list_parameters',
                       ListParameters.Request())
        assert {'rate_hz', 'use_sim_time', 'start_type_description_service'} <= set(
            listed.result.names
        )
        got = _call(executor, node, GetParameters, f'{NODE}/get_parameters',
                    GetParameters.Request(names=['rate_hz', 'use_sim_time']))
        assert [(v.type, v.double_value, v.bool_value) for v in got.values] == [
            (3, 250.0, False),  # DOUBLE as -p gave it; BOOL
            (1, 0.0, False),
        ]
        described = _call(executor, node, DescribeParameters, f'{NODE}/describe_parameters',
                          DescribeParameters.Request(names=['start_type_description_service']))
        assert described.descriptors[0].read_only
        change = ParameterMsg(name='rate_hz', value=ParameterValue(type=3, double_value=10.0))
        results = _call(executor, node, SetParameters, f'{NODE}/set_parameters',
                        SetParameters.Request(parameters=[change]))
        assert not results.results[0].successful  # a running node takes no changes
        assert results.results[0].reason == 'Trying to set a read-only parameter: rate_hz.'
        again = _call(executor, node, GetParameters, f'{NODE}/get_parameters',
                      GetParameters.Request(names=['rate_hz']))
        assert again.values[0].double_value == 250.0
        assert publisher_process.poll() is None
    finally:
        rclpy.shutdown(context=context)


# rcl_interfaces/srv/GetParameters as rmw_cyclonedds serialises it: the header, then the fields.
# (The member names are the project's: Cyclone's XTypes matching compares them; rmw_cyclonedds
# announces no type information and matches on the type's name alone.)


@dataclass
class ParameterValue_(IdlStruct, typename='rcl_interfaces::msg::dds_::ParameterValue_'):
    type: t.uint8 = 0  # noqa: A003
    bool_value: bool = False
    integer_value: t.int64 = 0
    double_value: t.float64 = 0.0
    string_value: str = ''
    byte_array_value: t.sequence[t.byte] = field(default_factory=list)
    bool_array_value: t.sequence[bool] = field(default_factory=list)
    integer_array_value: t.sequence[t.int64] = field(default_factory=list)
    double_array_value: t.sequence[t.float64] = field(default_factory=list)
    string_array_value: t.sequence[str] = field(default_factory=list)


@dataclass
class Request(IdlStruct, typename='rcl_interfaces::srv::dds_::GetParameters_Request_'):
    client_guid: t.uint64 = 0
    sequence_number: t.int64 = 0
    names: t.sequence[str] = field(default_factory=list)


@dataclass
class Response(IdlStruct, typename='rcl_interfaces::srv::dds_::GetParameters_Response_'):
    client_guid: t.uint64 = 0
    sequence_number: t.int64 = 0
    values: t.sequence[ParameterValue_] = field(default_factory=list)


def test_requests_and_replies_carry_rmw_cyclonedds_header(publisher_process, dds_on_loopback):
    participant = DomainParticipant(int(dds_on_loopback['ROS_DOMAIN_ID']))
    qos = Qos(
        Policy.Reliability.Reliable(max_blocking_time=10**9),
        Policy.History.KeepLast(10),
        Policy.DataRepresentation(use_cdrv0_representation=True),
    )
    writer = DataWriter(
        participant, Topic(participant, f'rq{NODE}/get_parametersRequest', Request), qos=qos
    )
    reader = DataReader(
        participant, Topic(participant, f'rr{NODE}/get_parametersReply', Response), qos=qos
    )
    end = time.monotonic() + 20
    while time.monotonic() < end and not (
        writer.get_publication_matched_status().current_count
        and reader.get_subscription_matched_status().current_count
    ):
        time.sleep(0.05)
    # This raw client announces no client id, so the server cannot wait for its reply reader (as
    # with rmw_cyclonedds): a reply written before the server's writer matched that reader is
    # lost. Ask again until one comes, as such a client must.
    replies: list = []
    sent = 0.0
    while time.monotonic() < end and not replies:
        if time.monotonic() - sent > 0.5:
            writer.write(
                Request(client_guid=0x1234_5678_9ABC, sequence_number=7, names=['rate_hz'])
            )
            sent = time.monotonic()
        replies = [r for r in reader.take(10) if isinstance(r, Response)]
        time.sleep(0.02)
    assert replies, 'no reply'
    reply = replies[0]
    # the header echoed: the client's id and its request's number
    assert (reply.client_guid, reply.sequence_number) == (0x1234_5678_9ABC, 7)
    assert [(v.type, v.double_value) for v in reply.values] == [(3, 250.0)]
