"""MJCF scene of a shaking table, built with ``mujoco.MjSpec`` from one table description."""

from mjcf.builder import BuildOptions, build, build_spec, write_xml
from mjcf.description import TableDescription, actuator_strokes, load_payload, load_table, rotation_matrix
from mjcf.errors import DescriptionError, MjcfError
from mjcf.model import TableModel

__all__ = [
    "BuildOptions",
    "DescriptionError",
    "MjcfError",
    "TableDescription",
    "TableModel",
    "actuator_strokes",
    "build",
    "build_spec",
    "load_payload",
    "load_table",
    "rotation_matrix",
    "write_xml",
]
