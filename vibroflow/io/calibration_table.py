"""The typed table of calibration.toml (vibroflow.io.calibration_file): the value types each
key is checked against and the `Table` record, which keeps undeclared keys and the file's key
order, so that a table written and read again is the same text."""
from __future__ import annotations

import math
from typing import Annotated, Any

import numpy as np
from pydantic import BaseModel, ConfigDict, PlainValidator, PrivateAttr, model_validator


def _finite(v):
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
            or not math.isfinite(v):
        raise ValueError("must be a finite number")
    return v


def _number(v):
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
        raise ValueError("must be a number (nan where it could not be estimated)")
    return v


def _count(v):
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
        raise ValueError("must be a whole number >= 0")
    return v


def _text(v):
    if not isinstance(v, str):
        raise ValueError("must be a string")
    return v


# the values keep the type they are given (an int stays an int, so the file is written back as
# it was read); NaN and inf are allowed where a value may be unknown
Finite = Annotated[float, PlainValidator(_finite)]
Number = Annotated[float, PlainValidator(_number)]
Count = Annotated[int, PlainValidator(_count)]
Text = Annotated[str, PlainValidator(_text)]


def _plain(obj):
    """A value as TOML writes it: numpy scalars as Python's, None left out, records as tables."""
    if isinstance(obj, Table):
        return obj.to_toml_dict()
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items() if v is not None}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, (np.floating, float)):
        return float(obj)
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


class Table(BaseModel):
    """One table of calibration.toml: declared keys typed, others kept, the key order kept."""

    model_config = ConfigDict(frozen=True, extra="allow")
    _order: tuple = PrivateAttr(default=())

    @model_validator(mode="wrap")
    @classmethod
    def _keep_order(cls, data: Any, handler):
        rec = handler(data)
        if isinstance(data, dict):
            rec._order = tuple(str(k) for k in data)
        return rec

    def to_toml_dict(self) -> dict:
        """The table as the file holds it: its keys in the file's order (declared keys given
        otherwise after them), None left out, sub-tables as dicts."""
        values = {**{k: getattr(self, k) for k in type(self).model_fields},
                  **(self.__pydantic_extra__ or {})}
        keys = [*self._order, *(k for k in values if k not in self._order)]
        return {k: _plain(values[k]) for k in keys if values.get(k) is not None}
