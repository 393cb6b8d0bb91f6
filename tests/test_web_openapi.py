"""``/openapi.json`` names a typed model for every JSON answer of the API and documents every field.

Every response of every ``/api/...`` operation (errors too) has JSON content whose schema is a
``$ref`` to a named component (or an array of one), except the EEPROM image's binary body; no
schema anywhere is a free-form object (``additionalProperties: true``, or an object or value
without any type), except the few fields named in :data:`FREE_FORM` with the reason; and every
property of every component schema has a non-empty description.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from station.web.app import create_app

#: (component, property) -> why that field is a free-form JSON value; everything below it is free too.
FREE_FORM = {
    ("CalibrationParameters", "quality"): "fit-quality figures whose keys depend on how the parameter set was made "
    "(the fit's method, simulator truth, an EEPROM image); free-form in the station-params/1 format itself",
    ("CalibrationParameters", "source"): "provenance whose keys depend on where the parameter set came from; "
    "free-form in the station-params/1 format itself",
    ("DiagnosisReady", "report"): "the station-diagnosis/1 document of station.diagnose, passed through verbatim: "
    "versioned by its own 'format' field and documented in station/diagnose/report.py",
    ("ValidationError", "input"): "FastAPI's request validation error: the rejected input is whatever was sent",
    ("ValidationError", "ctx"): "FastAPI's request validation error: its context depends on the failed constraint",
}
#: (path, method, status) of responses whose body is not JSON.
NOT_JSON = {("/api/units/{serial}/eeprom.bin", "get", "200"): "application/octet-stream"}
_TYPED = ("type", "$ref", "anyOf", "oneOf", "allOf", "enum", "const")


@pytest.fixture(scope="module")
def doc(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Any]]:
    db = tmp_path_factory.mktemp("openapi") / "empty.sqlite"
    with TestClient(create_app(f"sqlite:///{db}")) as client:
        yield client.get("/openapi.json").json()


def _named(schema: dict[str, Any]) -> bool:
    """A ``$ref`` to a component, or an array of one."""
    if "$ref" in schema:
        return schema["$ref"].startswith("#/components/schemas/")
    return schema.get("type") == "array" and "$ref" in schema.get("items", {})


def _free_form(schema: dict[str, Any]) -> str | None:
    """Why ``schema`` itself is untyped (None: it is typed)."""
    if not any(k in schema for k in _TYPED):
        return "no type"
    if schema.get("additionalProperties") is True:
        return "additionalProperties: true"
    closed = schema.get("additionalProperties") is False or isinstance(schema.get("additionalProperties"), dict)
    if schema.get("type") == "object" and not schema.get("properties") and not closed:
        return "an object without properties"
    return None


def _walk(schema: Any, where: str) -> Iterator[tuple[str, str]]:
    """(where, why) of every free-form schema in and below ``schema``."""
    if not isinstance(schema, dict):
        return
    why = _free_form(schema)
    if why is not None:
        yield where, why
    for key in ("items", "additionalProperties"):
        if isinstance(schema.get(key), dict):
            yield from _walk(schema[key], f"{where}.{key}")
    for key in ("anyOf", "oneOf", "allOf"):
        for k, sub in enumerate(schema.get(key, ())):
            yield from _walk(sub, f"{where}.{key}[{k}]")
    for name, sub in schema.get("properties", {}).items():
        yield from _walk(sub, f"{where}.{name}")


def _operations(doc: dict[str, Any]) -> Iterator[tuple[str, str, dict[str, Any]]]:
    for path, item in doc["paths"].items():
        for method, op in item.items():
            if method in ("get", "post", "put", "patch", "delete"):
                yield path, method, op


def test_every_api_response_is_a_named_model(doc: dict[str, Any]) -> None:
    bad = []
    api = [(p, m, op) for p, m, op in _operations(doc) if p.startswith("/api/")]
    assert len(api) >= 7
    for path, method, op in api:
        for status, response in op["responses"].items():
            content = response.get("content", {})
            if (path, method, status) in NOT_JSON:
                if NOT_JSON[path, method, status] not in content:
                    bad.append(f"{method.upper()} {path} {status}: no {NOT_JSON[path, method, status]} body")
                continue
            schema = content.get("application/json", {}).get("schema")
            if schema is None or not _named(schema):
                bad.append(f"{method.upper()} {path} {status}: {schema!r}")
    assert bad == [], "responses without a named model:\n" + "\n".join(bad)


def test_request_bodies_and_parameters_are_typed(doc: dict[str, Any]) -> None:
    bad = []
    for path, method, op in _operations(doc):
        body = op.get("requestBody", {}).get("content", {}).get("application/json", {}).get("schema")
        if body is not None and not (_named(body) or all(_named(s) or s == {"type": "null"}
                                                         for s in body.get("anyOf", [{}]))):
            bad.append(f"{method.upper()} {path} body: {body!r}")
        for param in op.get("parameters", ()):
            bad += [f"{method.upper()} {path} {param['name']}{w}: {why}" for w, why in _walk(param["schema"], "")]
            if not param.get("description") and param["in"] != "path":
                bad.append(f"{method.upper()} {path} {param['name']}: no description")
    assert bad == [], "\n".join(bad)


def test_no_schema_is_free_form(doc: dict[str, Any]) -> None:
    bad = []
    for name, schema in doc["components"]["schemas"].items():
        if _free_form(schema) is not None:
            bad.append(f"{name}: {_free_form(schema)}")
        for prop, sub in schema.get("properties", {}).items():
            if (name, prop) not in FREE_FORM:
                bad += [f"{name}{where}: {why}" for where, why in _walk(sub, f".{prop}")]
    for path, method, op in _operations(doc):
        for status, response in op["responses"].items():
            for media, content in response.get("content", {}).items():
                if media == "application/json":
                    bad += [f"{method.upper()} {path} {status}{w}: {why}" for w, why in _walk(content["schema"], "")]
    assert bad == [], "free-form schemas:\n" + "\n".join(bad)
    for (name, prop), reason in FREE_FORM.items():  # the exceptions exist (no stale entry) and say why
        assert prop in doc["components"]["schemas"][name]["properties"] and reason


def test_every_component_property_is_described(doc: dict[str, Any]) -> None:
    missing = [f"{name}.{prop}" for name, schema in doc["components"]["schemas"].items()
               for prop, sub in schema.get("properties", {}).items() if not str(sub.get("description", "")).strip()]
    assert missing == [], "properties without a description:\n" + "\n".join(missing)


@pytest.mark.parametrize(("name", "prop", "unit"), [
    ("StationStatus", "remaining_s", "(s"), ("StepProgress", "hold_s", "(s)"), ("RunSummary", "duration_s", "(s"),
    ("TriadCalibration", "bias_static", "m/s^2"), ("TriadCalibration", "bias_static", "rad/s"),
    ("CalibrationParameters", "sample_period_s", "(s)"), ("ShiftStats", "units_per_hour", "1/h"),
    ("RigState", "rate_dps", "deg/s"), ("DiagnosisReady", "elapsed_s", "(s)"),
])
def test_descriptions_name_the_unit(doc: dict[str, Any], name: str, prop: str, unit: str) -> None:
    assert unit in doc["components"]["schemas"][name]["properties"][prop]["description"]


def test_the_checks_catch_free_form_and_unnamed_schemas() -> None:
    assert _free_form({"type": "object", "additionalProperties": True}) == "additionalProperties: true"
    assert _free_form({"title": "Input"}) == "no type"
    assert _free_form({"type": "object"}) == "an object without properties"
    assert _free_form({"type": "array", "items": {"type": "number"}}) is None
    assert _free_form({"type": "object", "properties": {}, "additionalProperties": False}) is None  # takes nothing
    assert [w for w, _ in _walk({"type": "array", "items": {"type": "object", "additionalProperties": True}}, "")
            ] == [".items"]
    assert _named({"type": "array", "items": {"$ref": "#/components/schemas/RunSummary"}})
    assert not _named({"type": "array", "items": {"type": "object", "additionalProperties": True}})


def test_old_style_untyped_answers_fail(tmp_path: Path) -> None:
    """The checks fail on an endpoint that answers ``dict[str, Any]`` (as every JSON endpoint once did)."""
    app = create_app(f"sqlite:///{tmp_path / 'x.sqlite'}")

    @app.get("/api/untyped")
    def untyped() -> dict[str, Any]:
        return {}

    doc = app.openapi()
    schema = doc["paths"]["/api/untyped"]["get"]["responses"]["200"]["content"]["application/json"]["schema"]
    assert not _named(schema) and [why for _, why in _walk(schema, "")] == ["additionalProperties: true"]
