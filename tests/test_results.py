"""The result base (issue 23, item 3): one JSON conversion, one save, for every result."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numpy as np
import pytest

from rotor_env.diagnosis.from_rig import RigDiagnosis
from rotor_env.diagnosis.from_vectors import VectorDiagnosis
from rotor_env.diagnosis.result import Diagnosis, NotIdentifiableResult
from rotor_env.results import Result, jsonable


def test_jsonable_gives_plain_json_values():
    value = {1: np.float64(0.5), "a": (np.int32(3), np.bool_(True)), "nan": float("nan"),
             "inf": np.float32(np.inf), "arr": np.array([[1.0, np.nan], [2.0, 3.0]]), "s": np.str_("x")}
    out = jsonable(value)
    assert out == {"1": 0.5, "a": [3, True], "nan": None, "inf": None, "arr": [[1.0, None], [2.0, 3.0]], "s": "x"}
    assert type(out["a"][0]) is int and type(out["a"][1]) is bool
    # what json itself writes for it: strict JSON (no NaN token), read back the same
    assert json.loads(json.dumps(out, allow_nan=False)) == out


def test_every_result_shares_the_base():
    for cls in (Diagnosis, NotIdentifiableResult, VectorDiagnosis, RigDiagnosis):
        assert issubclass(cls, Result)
        assert cls.to_json is Result.to_json and cls.save is Result.save


@dataclass
class _Numbers(Result):
    x: float

    def to_dict(self) -> dict:
        return {"x": np.float64(self.x), "values": np.arange(3.0)}


def test_save_writes_the_json_and_never_overwrites_silently(tmp_path):
    path = tmp_path / "result.json"
    _Numbers(math.pi).save(path)
    assert json.loads(path.read_text()) == {"x": math.pi, "values": [0.0, 1.0, 2.0]}
    with pytest.raises(FileExistsError):
        _Numbers(1.0).save(path)
    assert json.loads(path.read_text())["x"] == math.pi  # untouched
    _Numbers(1.0).save(path, overwrite=True)
    assert json.loads(path.read_text())["x"] == 1.0
