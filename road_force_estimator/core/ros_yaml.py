"""YAML values as ROS 2 reads them: the scalar rules of rcl's parameter parser, in Python.

A node started with ``--ros-args --params-file FILE`` (or ``-p NAME:=VALUE``) gets its values
from ``rcl_yaml_param_parser`` (``parse.c``, ``get_value``), which does not follow YAML 1.1
(PyYAML's schema) but its own rules, tried in this order on each scalar:

1. a ``!!str`` tag, or a single- or double-quoted scalar: the string;
2. ``Y y yes Yes YES true True TRUE on On ON`` (and the same for false: ``N n no ... off``):
   a bool;
3. C's ``strtoll(text, &end, 0)`` consuming the whole text without overflow: an int64
   (``42``, ``-7``, ``0x1A`` = 26, ``010`` = 8: octal);
4. C's ``strtod`` consuming the whole text without a range error (``.nan``, ``.inf``,
   ``-.inf`` first): a double (``1.1e6``, ``1e-05``, ``5.``, ``.5``, ``inf``, ``0x1p3``);
5. else the string (``1_000``, ``~``, ``null``, ``1:20`` stay strings).

A sequence's items must all have one type ("Sequence should be of same type", rcl's words):
``[1.0e6, 1080000]`` is refused, ``[1000000, 1080000]`` is an integer array. An alias is
refused (rcl: "Will not support aliasing"), and so is a key given twice in one mapping.
Mapping keys stay strings. PyYAML does the parsing (events and nodes), this module the
resolution, so that an offline command reads a file exactly as the node does.
"""
from __future__ import annotations

import math
import re
import sys
from typing import Any

import yaml
from yaml.nodes import MappingNode, ScalarNode, SequenceNode

__all__ = ['load', 'ros_scalar']

_TRUE = frozenset('Y y yes Yes YES true True TRUE on On ON'.split())
_FALSE = frozenset('N n no No NO false False FALSE off Off OFF'.split())
_SPACE = '[ \\t\\n\\v\\f\\r]*'          # C's isspace, skipped first by strtoll and strtod
_STRTOLL = re.compile(f'{_SPACE}([+-]?)(?:0[xX]([0-9a-fA-F]+)|(0[0-7]*)|([1-9][0-9]*))')
_DECIMAL = re.compile(f'{_SPACE}[+-]?(?:[0-9]+\\.?[0-9]*|\\.[0-9]+)(?:[eE][+-]?[0-9]+)?')
_HEX_FLOAT = re.compile(f'{_SPACE}([+-]?)0[xX]((?:[0-9a-fA-F]+\\.?[0-9a-fA-F]*|'
                        f'\\.[0-9a-fA-F]+)(?:[pP][+-]?[0-9]+)?)')
_SPECIAL = re.compile(f'{_SPACE}[+-]?(?:inf|infinity|nan(?:\\([0-9A-Za-z_]*\\))?)',
                      re.IGNORECASE)
_DOT_SPECIAL = frozenset('.nan .NaN .NAN .inf .Inf .INF +.inf +.Inf +.INF -.inf -.Inf -.INF'
                         .split())
_INT64 = (-(1 << 63), (1 << 63) - 1)
_STR_TAG = 'tag:yaml.org,2002:str'
_ROS_TAG = 'tag:ros.org,rcl:scalar'     # a scalar rcl resolves by its text (rules 2-5)


def _strtoll(text: str) -> int | None:
    """strtoll(text, &end, 0) when it consumes ``text`` whole without overflow, else None."""
    m = _STRTOLL.fullmatch(text)
    if m is None:
        return None
    sign, hex_digits, octal, decimal = m.groups()
    value = (int(hex_digits, 16) if hex_digits is not None else
             int(octal, 8) if octal is not None else int(decimal))
    value = -value if sign == '-' else value
    return value if _INT64[0] <= value <= _INT64[1] else None   # ERANGE: not an int


def _strtod(text: str) -> float | None:
    """strtod(text, &end) (C locale) when it consumes ``text`` whole without a range error."""
    if text in _DOT_SPECIAL:
        value = float(text.replace('.', ''))
        return value
    if _SPECIAL.fullmatch(text):
        body = text.strip().lower()
        return math.nan if 'nan' in body else float(body)
    m = _HEX_FLOAT.fullmatch(text)
    if m is not None:
        body = m.group(2)
        if 'p' not in body.lower():
            body += 'p0'
        value = float.fromhex(('-' if m.group(1) == '-' else '') + '0x' + body)
    elif _DECIMAL.fullmatch(text):
        value = float(text)
        if value == 0.0 and any(c in '123456789' for c in text.lower().split('e')[0]):
            return None          # underflow to zero: ERANGE
    else:
        return None
    if math.isinf(value) or (value != 0.0 and abs(value) < sys.float_info.min):
        return None              # overflow or a subnormal result: ERANGE
    return value


def ros_scalar(text: str) -> Any:
    """A plain (unquoted, untagged) scalar as rcl reads it: bool, int, float or str."""
    if text in _TRUE:
        return True
    if text in _FALSE:
        return False
    for convert in (_strtoll, _strtod):
        value = convert(text)
        if value is not None:
            return value
    return text


class _Loader(yaml.SafeLoader):
    """PyYAML's parser with rcl's resolution of scalars (no YAML 1.1 schema)."""

    def compose_scalar_node(self, anchor):
        event = self.peek_event()
        explicit_str = event.tag in (_STR_TAG, '!!str')
        quoted = event.style in ("'", '"')
        node = super().compose_scalar_node(anchor)
        node.tag = _STR_TAG if explicit_str or quoted else _ROS_TAG
        return node

    def construct_ros_scalar(self, node: ScalarNode) -> Any:
        if not node.value and node.style is None:
            raise ValueError(f'line {node.start_mark.line + 1}: no value')
        return ros_scalar(node.value)

    def construct_ros_mapping(self, node: MappingNode) -> dict:
        out: dict[str, Any] = {}
        lines: dict[str, int] = {}
        for key_node, value_node in node.value:
            line = key_node.start_mark.line + 1
            if not isinstance(key_node, ScalarNode):
                raise ValueError(f'line {line}: a key must be a name')
            key = key_node.value
            if key in lines:
                raise ValueError(f'line {line}: key {key!r} given twice (first on line '
                                 f'{lines[key]}): remove one')
            lines[key] = line
            out[key] = self.construct_object(value_node, deep=True)
        return out

    def construct_ros_sequence(self, node: SequenceNode) -> list:
        items = []
        for item in node.value:
            line = item.start_mark.line + 1
            if not isinstance(item, ScalarNode):
                raise ValueError(f'line {line}: a sequence holds values, not '
                                 f'{"sequences" if isinstance(item, SequenceNode) else "maps"}')
            items.append(self.construct_object(item, deep=True))
        kinds = {_kind(v) for v in items}
        if len(kinds) > 1:
            raise ValueError(f'line {node.start_mark.line + 1}: sequence should be of same '
                             f'type (rcl): {", ".join(sorted(kinds))} mixed in {items!r}')
        return items


def _kind(value: Any) -> str:
    return ('bool' if isinstance(value, bool) else 'integer' if isinstance(value, int) else
            'double' if isinstance(value, float) else 'string')


_Loader.add_constructor(_ROS_TAG, _Loader.construct_ros_scalar)
_Loader.add_constructor('tag:yaml.org,2002:map', _Loader.construct_ros_mapping)
_Loader.add_constructor('tag:yaml.org,2002:seq', _Loader.construct_ros_sequence)
_Loader.add_constructor(_STR_TAG, yaml.SafeLoader.construct_yaml_str)
_Loader.yaml_implicit_resolvers = {}   # every plain scalar comes to construct_ros_scalar


def load(text: str) -> Any:
    """The YAML document ``text`` with rcl's values (see the module's rules).

    Raises
    ------
    ValueError
        An alias, a key given twice, a sequence of mixed types or of sequences, an empty
        plain value; the message has the line. ``yaml.YAMLError`` for invalid YAML.
    """
    for event in yaml.parse(text, Loader=yaml.SafeLoader):
        if isinstance(event, yaml.AliasEvent):
            raise ValueError(f'line {event.start_mark.line + 1}: YAML alias *{event.anchor} '
                             'refused (parameter files have no anchors or aliases)')
    return yaml.load(text, Loader=_Loader)  # noqa: S506 (a SafeLoader without its resolvers)
