"""The plan schema's name is one constant, and the published JSON Schema declares the same name."""

import json
from pathlib import Path

import pytest

import planner
from planner.common.plans import PLAN_SCHEMA, load_plan
from rapt.errors import FileFormatError

SCHEMA = json.loads((Path(planner.__file__).parent / "plan.schema.json").read_text())


def test_the_published_schema_names_the_constant():
    assert SCHEMA["$id"] == PLAN_SCHEMA
    assert SCHEMA["properties"]["schema"]["const"] == PLAN_SCHEMA


def test_a_plan_of_another_schema_is_refused(tmp_path):
    path = tmp_path / "plan.json"
    path.write_text(json.dumps({"schema": PLAN_SCHEMA.replace("/1", "/0")}))
    with pytest.raises(FileFormatError, match=rf"is not a {PLAN_SCHEMA} plan \(schema 'rapt.plan/0'\)"):
        load_plan(path)
