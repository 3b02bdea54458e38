"""
The calls the DDS transport makes below cyclonedds' public Python API, all of them here.

Why: rmw_cyclonedds puts the rosidl CDR of a message on the wire, and the package serialises each
message once, with the project's type store, into exactly those bytes. cyclonedds-python's public
DataWriter.write and DataReader.take (de)serialise its own IdlStruct objects instead, and take
hands back only what its IDL class can decode (a Humble GID is 24 bytes, Jazzy's 16). So raw CDR
is written and taken through cyclonedds' C layer (`_clayer.ddspy_write`, `ddspy_take`) on an
entity's handle (`_ref`). An entity is deleted at once (`_delete`, dropped from `_entities`)
rather than when Python happens to collect it, so that a destroyed publisher leaves the graph
when rclpy's would. These names are private: setup.py pins cyclonedds below 12, and
test/test_cyclone_private.py fails naming what is missing if an installed cyclonedds lacks one.
"""

from __future__ import annotations

from typing import Any

import cyclonedds._clayer as _clayer
from cyclonedds.core import Entity


def write_cdr(writer: Any, payload: bytes) -> int:
    """Write one serialised sample (CDR with its 4-byte header) with a DataWriter; <0 on error."""
    return _clayer.ddspy_write(writer._ref, payload)


def take_cdr(reader: Any, mask: int, count: int) -> Any:
    """Take up to `count` samples as (CDR bytes, SampleInfo) pairs; an int (<0) on error."""
    return _clayer.ddspy_take(reader._ref, mask, count)


def delete_entity(entity: Any) -> None:
    """Delete a Cyclone entity now (and its children), not when Python collects the object."""
    if entity._entities.get(entity._ref) is entity:
        del entity._entities[entity._ref]
        entity._delete(entity._ref)


def missing(participant: Any = None) -> list[str]:
    """Return the private names an installed cyclonedds lacks (`participant`: a live entity)."""
    out = [
        f'cyclonedds._clayer.{name}'
        for name in ('ddspy_write', 'ddspy_take')
        if not callable(getattr(_clayer, name, None))
    ]
    if not callable(getattr(Entity, '_delete', None)):
        out.append('cyclonedds.core.Entity._delete')
    if not callable(getattr(getattr(Entity, '_entities', None), 'get', None)):
        out.append('cyclonedds.core.Entity._entities')
    if participant is not None and not isinstance(getattr(participant, '_ref', None), int):
        out.append('cyclonedds.core.Entity._ref')
    return out
