"""
runtime/dds/idl.py: the DDS structs generated from the type store describe ROS 2's types.

Each generated struct's XTypes type information (what Cyclone announces in discovery, and what a
reader declared from ROS 2's IDL is matched against) equals that of the struct written out by hand
from the .msg and .srv files (idl_reference.py), services' request header included.
"""

from dataclasses import dataclass

from cloth_bench_ros.runtime.dds import idl
from cyclonedds.idl import IdlStruct
from cyclonedds.idl import types as t
from idl_reference import REFERENCE
import pytest


@dataclass
class Narrow(IdlStruct, typename='builtin_interfaces::msg::dds_::Time_'):
    """builtin_interfaces/Time with a 16-bit nanosec: not the type ROS 2 declares."""

    sec: t.int32
    nanosec: t.uint16


@pytest.mark.parametrize('ros_type', sorted(REFERENCE))
def test_a_generated_struct_has_the_type_information_of_the_hand_written_one(ros_type):
    generated, written = idl.dds_type(ros_type), REFERENCE[ros_type]
    assert generated.__idl__.get_type_info() == written.__idl__.get_type_info()
    assert generated.__idl__.get_type_id() == written.__idl__.get_type_id()
    assert generated is idl.dds_type(ros_type)  # made once


def test_a_different_struct_has_different_type_information():
    # The comparison above can fail: one field of another width is told apart.
    assert (
        Narrow.__idl__.get_type_info()
        != idl.dds_type('builtin_interfaces/msg/Time').__idl__.get_type_info()
    )


def test_the_graph_types_are_jazzys_and_an_unknown_type_is_refused():
    gid = idl.dds_type('rmw_dds_common/msg/Gid')
    assert gid is idl.Gid_ and idl.dds_type('rmw_dds_common/msg/ParticipantEntitiesInfo') is (
        idl.ParticipantEntitiesInfo_
    )
    with pytest.raises(ValueError, match='no DDS type'):
        idl.dds_type('nobody_msgs/msg/Nothing')
