"""The models mirror openapi/openapi.json: every field a model declares is a
property of the schema it names, with a compatible type."""

import dataclasses
import json
import pathlib
import typing

from jointd_client.errors import Problem
from jointd_client.models import MODELS

DOC = json.loads((pathlib.Path(__file__).resolve().parents[3] / "openapi" / "openapi.json").read_text())
SCHEMAS = DOC["components"]["schemas"]
JSON_TYPES = {int: {"integer"}, float: {"number", "integer"}, str: {"string"}, bool: {"boolean"},
              list: {"array"}, dict: {"object"}}


def schema_types(prop):
    t = prop.get("type")
    if t is None:
        return None  # a $ref, oneOf or free value: not checked further
    return set(t) if isinstance(t, list) else {t}


def python_types(hint):
    args = typing.get_args(hint)
    origin = typing.get_origin(hint)
    if origin is typing.Union:
        inner = [a for a in args if a is not type(None)]
        return {typing.get_origin(a) or a for a in inner}, type(None) in args
    return {origin or hint}, False


def test_every_model_field_is_in_its_schema_with_a_compatible_type():
    for model in [*MODELS, Problem]:
        schema = SCHEMAS[model.SCHEMA]
        props = schema["properties"]
        hints = typing.get_type_hints(model)
        for f in dataclasses.fields(model):
            if f.name == "raw":
                continue
            assert f.name in props, f"{model.__name__}.{f.name} is not in schema {model.SCHEMA}"
            wanted = schema_types(props[f.name])
            if wanted is None:
                continue
            kinds, optional = python_types(hints[f.name])
            if typing.Any in kinds:
                continue
            allowed = set().union(*(JSON_TYPES.get(k, set()) for k in kinds))
            assert wanted - {"null"} <= allowed, f"{model.__name__}.{f.name}: {wanted} vs {kinds}"
            if f.name in schema.get("required", []) and "null" not in wanted:
                continue
            assert optional or "null" not in wanted, f"{model.__name__}.{f.name} may be null"
