"""Writes jointd_client/schema.py from openapi/openapi.json: one TypedDict
per object schema, a Literal per string enum, an alias per union, so that
mypy checks what a script reads from the daemon's answers.

    python3 clients/python/gen_schema.py          # rewrite the module
    python3 clients/python/gen_schema.py --check  # exit 1 if it is stale

tests/test_schema.py runs the check: a schema changed in the daemon and not
here fails CI, not a user's script.
"""

import json
import keyword
import pathlib
import sys
from typing import Any, Dict, List, Tuple

HERE = pathlib.Path(__file__).resolve().parent
DOC = HERE.parents[1] / "openapi" / "openapi.json"
OUT = HERE / "jointd_client" / "schema.py"

HEADER = '''"""The daemon's schemas as types (generated from openapi/openapi.json by
clients/python/gen_schema.py: do not edit by hand).

Each object schema is a TypedDict (the answers stay plain dicts at run time);
fields the schema does not require are `total=False` in a second class.
"""

from typing import Any, Dict, List, Literal, Optional, TypedDict, Union


'''


def ref_name(ref: str) -> str:
    return ref.rsplit("/", 1)[-1]


def py_type(s: Dict[str, Any]) -> str:
    """The annotation of schema `s` (a string: every name is quoted by the caller's module order)."""
    if "$ref" in s:
        return f'"{ref_name(s["$ref"])}"'
    for key in ("oneOf", "anyOf"):
        if key in s:
            parts = [p for p in s[key]]
            nullable = any(p.get("type") == "null" for p in parts)
            rest = [py_type(p) for p in parts if p.get("type") != "null"]
            rest = list(dict.fromkeys(rest))
            inner = rest[0] if len(rest) == 1 else f"Union[{', '.join(rest)}]"
            return f"Optional[{inner}]" if nullable else inner
    if "allOf" in s:
        parts = [py_type(p) for p in s["allOf"]]
        return parts[0] if len(parts) == 1 else "Dict[str, Any]"
    t = s.get("type")
    if isinstance(t, list):
        nullable = "null" in t
        rest = [x for x in t if x != "null"]
        inner = py_type({**s, "type": rest[0]}) if len(rest) == 1 else "Any"
        return f"Optional[{inner}]" if nullable else inner
    if "enum" in s and t == "string":
        return "Literal[" + ", ".join(json.dumps(v) for v in s["enum"]) + "]"
    if t == "string":
        return "str"
    if t == "integer":
        return "int"
    if t == "number":
        return "float"
    if t == "boolean":
        return "bool"
    if t == "null":
        return "None"
    if t == "array":
        return f"List[{py_type(s.get('items', {}))}]"
    if t == "object":
        extra = s.get("additionalProperties")
        if isinstance(extra, dict) and not s.get("properties"):
            return f"Dict[str, {py_type(extra)}]"
        return "Dict[str, Any]"
    return "Any"


def field_name(name: str) -> str:
    return name if name.isidentifier() and not keyword.iskeyword(name) else ""


def typed_dict(name: str, s: Dict[str, Any]) -> List[str]:
    props: Dict[str, Any] = s.get("properties", {})
    required = set(s.get("required", []))
    doc = " ".join(s.get("description", "").strip().split("\n\n")[0].split()).replace('"""', "'''")
    req = [(k, v) for k, v in sorted(props.items()) if k in required]
    opt = [(k, v) for k, v in sorted(props.items()) if k not in required]
    odd = [k for k in props if not field_name(k)]
    if odd:
        # A key that is not a Python name: the functional form takes it.
        fields = ", ".join(f"{json.dumps(k)}: {py_type(v)}" for k, v in sorted(props.items()))
        return [f"{name} = TypedDict({json.dumps(name)}, {{{fields}}}, total=False)", ""]
    lines: List[str] = []

    def body(items: List[Tuple[str, Any]]) -> List[str]:
        out = []
        for k, v in items:
            out.append(f"    {k}: {py_type(v)}")
            d = " ".join(v.get("description", "").strip().split("\n\n")[0].split())
            if d:
                out.append(f'    """{d.replace(chr(34) * 3, chr(39) * 3)}"""')
        return out or ["    pass"]

    if req and opt:
        lines.append(f"class _{name}Required(TypedDict):")
        lines += body(req)
        lines += ["", ""]
        lines.append(f"class {name}(_{name}Required, total=False):")
    elif opt:
        lines.append(f"class {name}(TypedDict, total=False):")
    else:
        lines.append(f"class {name}(TypedDict):")
    if doc:
        lines.append(f'    """{doc}"""')
        lines.append("")
    lines += body(req if not opt else opt) if not (req and opt) else body(opt)
    return lines + ["", ""]


def render(doc: Dict[str, Any]) -> str:
    schemas: Dict[str, Any] = doc["components"]["schemas"]
    out = [HEADER]
    aliases: List[str] = []
    classes: List[str] = []
    for name in sorted(schemas):
        s = schemas[name]
        if s.get("type") == "object" and "properties" in s:
            classes += typed_dict(name, s)
        else:
            aliases.append(f"{name} = {py_type(s).replace(chr(34), '') if '$ref' in str(s) else py_type(s)}")
    # The classes first (their annotations are strings, resolved lazily),
    # then the aliases, each after the names it uses.
    out += [c + "\n" for c in classes]
    defined = {n for n in schemas if n not in dict(a.split(" = ", 1) for a in aliases)}
    pending = [tuple(a.split(" = ", 1)) for a in aliases]
    while pending:
        ready = [(n, v) for n, v in pending
                 if all(m in defined for m in schemas if m != n and _names(v, m))]
        if not ready:
            raise SystemExit(f"alias cycle: {pending}")
        for n, v in ready:
            out.append(f"{n} = {v}\n")
            defined.add(n)
        pending = [p for p in pending if p not in ready]
    names = sorted(schemas)
    out.append("__all__ = [\n" + "".join(f"    {json.dumps(n)},\n" for n in names) + "]\n")
    text = "".join(out)
    return text.rstrip("\n") + "\n"


def _names(text: str, name: str) -> bool:
    """True if `name` appears in `text` as a whole word."""
    import re
    return re.search(rf"\b{re.escape(name)}\b", text) is not None


def main() -> int:
    text = render(json.loads(DOC.read_text()))
    if "--check" in sys.argv[1:]:
        if not OUT.exists() or OUT.read_text() != text:
            print(f"{OUT} is stale: run python3 {pathlib.Path(__file__).name}", file=sys.stderr)
            return 1
        return 0
    OUT.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
