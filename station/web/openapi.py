"""The application class: FastAPI with an OpenAPI document that describes every field.

FastAPI's own request validation error schemas (``HTTPValidationError``, ``ValidationError``, the body of
every 422 answer to a malformed request) come without field descriptions; :class:`StationAPI` adds them.
"""

from __future__ import annotations

from typing import Any

from fastapi import FastAPI

#: Descriptions of the fields of FastAPI's request validation error schemas, by schema and field.
VALIDATION_ERROR_FIELDS = {
    "HTTPValidationError": {"detail": "what is wrong with the request, one entry per problem"},
    "ValidationError": {
        "loc": "where: 'path', 'query', 'header' or 'body', then the parameter's or field's name (and index)",
        "msg": "what is wrong, in words",
        "type": "the kind of problem, e.g. 'missing', 'int_parsing', 'greater_than_equal'",
        "input": "the rejected input as received",
        "ctx": "the constraint that failed, e.g. {'ge': 1}",
    },
}


class StationAPI(FastAPI):
    """The station's web application (:func:`station.web.app.create_app` builds it)."""

    def openapi(self) -> dict[str, Any]:
        if self.openapi_schema is not None:
            return self.openapi_schema
        doc = super().openapi()  # made once and kept
        schemas = doc.get("components", {}).get("schemas", {})
        for name, fields in VALIDATION_ERROR_FIELDS.items():
            for prop, schema in schemas.get(name, {}).get("properties", {}).items():
                schema.setdefault("description", fields.get(prop, ""))
        return doc


__all__ = ["VALIDATION_ERROR_FIELDS", "StationAPI"]
