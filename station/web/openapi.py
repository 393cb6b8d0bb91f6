"""The application class: FastAPI with an OpenAPI document that describes every field and every status.

FastAPI's own request validation error schemas (``HTTPValidationError``, ``ValidationError``, the body of
every 422 answer to a malformed request) come without field descriptions; :class:`StationAPI` adds them.
Every operation can answer 503 when the station database is unavailable (held locked by another process
past the stated wait, or its disk full; :func:`add_store_errors`): the document lists it on each.
"""

from __future__ import annotations

from typing import Any

from fastapi import FastAPI, Request
from fastapi.responses import JSONResponse

from station.store.opening import StoreError
from station.web.models.common import ErrorDetail

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
        for operations in doc.get("paths", {}).values():
            for operation in operations.values():
                responses = operation.setdefault("responses", {})
                responses.setdefault("503", {
                    "description": STORE_UNAVAILABLE,
                    "content": {"application/json": {"schema": {"$ref": "#/components/schemas/ErrorDetail"}}},
                })
        schemas.setdefault("ErrorDetail", ErrorDetail.model_json_schema())
        return doc


#: What a 503 means on every operation.
STORE_UNAVAILABLE = ("the station database is unavailable (locked by another process past the stated wait, or its "
                     "disk full), or the action is not possible on this station")


def add_store_errors(app: FastAPI) -> None:
    """Answer a database that is locked or full with 503 and one line (never a 500 with a traceback)."""

    async def unavailable(_request: Request, exc: Exception) -> JSONResponse:
        return JSONResponse({"detail": str(exc)}, status_code=503, headers={"Retry-After": "10"})

    app.add_exception_handler(StoreError, unavailable)


__all__ = ["STORE_UNAVAILABLE", "VALIDATION_ERROR_FIELDS", "StationAPI", "add_store_errors"]
