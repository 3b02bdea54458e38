"""
The private cyclonedds calls of runtime/dds/cyclone_private.py exist in the installed version.

A raw CDR sample written through them arrives through them (on the session's loopback-only
domain, test/conftest.py); a cyclonedds without one of them fails here naming it.
"""

from dataclasses import dataclass
import os
import time

from cloth_bench_ros.runtime.dds import cyclone_private
from cyclonedds.core import InstanceState, SampleState, ViewState
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import uint32
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic

ANY = SampleState.Any | ViewState.Any | InstanceState.Any


@dataclass
class Probe(IdlStruct, typename='cloth_bench_test::Probe'):
    """A one-field type: its CDR is the 4-byte header and a uint32."""

    value: uint32


def test_the_installed_cyclonedds_has_the_private_calls_the_transport_makes():
    participant = DomainParticipant(int(os.environ['ROS_DOMAIN_ID']))
    try:
        lacking = cyclone_private.missing(participant)
        assert not lacking, (
            'the installed cyclonedds lacks the private API that raw CDR writes and takes need: '
            f'{", ".join(lacking)}; install a cyclonedds that the pin in setup.py allows'
        )
        topic = Topic(participant, 'cloth_bench_private_probe', Probe)
        reader = DataReader(participant, topic)
        writer = DataWriter(participant, topic)
        assert cyclone_private.write_cdr(writer, Probe(value=7).serialize()) >= 0
        samples: list = []
        deadline = time.monotonic() + 5.0
        while not samples and time.monotonic() < deadline:
            samples = cyclone_private.take_cdr(reader, ANY, 8)
            assert not isinstance(samples, int), f'ddspy_take failed with {samples}'
            time.sleep(0.01)
        assert [Probe.deserialize(bytes(p)).value for p, info in samples if info.valid_data] == [7]
        cyclone_private.delete_entity(writer)
        cyclone_private.delete_entity(reader)
    finally:
        cyclone_private.delete_entity(participant)
