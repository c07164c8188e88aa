"""The committed OpenAPI spec: fresh, valid, and faithful to the physics tables."""

from __future__ import annotations

import json
import re

import pytest
from openapi_spec_validator import validate

from microbearing import physics
from microbearing.service.openapi import SPEC_PATH, spec_text
from microbearing.service.settings import settings_table


@pytest.fixture(scope="module")
def spec() -> dict:
    return json.loads(SPEC_PATH.read_text(encoding="utf-8"))


def test_committed_spec_is_not_stale():
    assert SPEC_PATH.read_text(encoding="utf-8") == spec_text(), (
        "openapi/openapi.json is stale: run `python -m microbearing.service.openapi` and commit it")


def test_spec_is_valid_openapi(spec):
    validate(spec)


def test_operation_ids_read_well(spec):
    ids = {op["operationId"] for item in spec["paths"].values() for op in item.values()}
    assert {"evaluate_friction", "evaluate_friction_batch", "create_sweep", "get_job", "cancel_job",
            "get_job_result", "get_health", "get_version", "list_materials"} <= ids


def test_every_error_response_is_a_problem(spec):
    for path, item in spec["paths"].items():
        for method, operation in item.items():
            codes = {int(code) for code in operation["responses"] if code.isdigit()}
            assert {404, 405, 422, 500} <= codes, (method, path)
            for code, response in operation["responses"].items():
                if int(code) >= 400:
                    assert list(response["content"]) == ["application/problem+json"], (method, path, code)
    assert "HTTPValidationError" not in spec["components"]["schemas"]


def test_request_schema_carries_units_bounds_and_defaults_from_the_table(spec):
    schema = spec["components"]["schemas"]["FrictionRequest"]
    assert schema["additionalProperties"] is False
    assert set(schema["required"]) == {n for n, p in physics.PARAMETERS.items() if p.required}
    for name, parameter in physics.PARAMETERS.items():
        field = schema["properties"][name]
        assert f"[{parameter.unit}]" in field["description"], name
        if parameter.kind == "bool":
            assert field["type"] == "boolean"
            continue
        assert field["type"] == ("integer" if parameter.kind == "int" else "number"), name
        low = "exclusiveMinimum" if parameter.exclusive_minimum else "minimum"
        high = "exclusiveMaximum" if parameter.exclusive_maximum else "maximum"
        assert field[low] == parameter.minimum and field[high] == parameter.maximum, name
        if not parameter.required:
            assert field["default"] == parameter.default, name


def test_sweep_union_has_a_required_tag(spec):
    body = spec["paths"]["/v1/sweeps"]["post"]["requestBody"]["content"]["application/json"]["schema"]
    assert body["discriminator"]["propertyName"] == "design"
    for ref in body["oneOf"]:
        member = spec["components"]["schemas"][ref["$ref"].rsplit("/", 1)[1]]
        assert "design" in member["required"]


def test_every_output_is_documented_with_its_unit(spec):
    schema = spec["components"]["schemas"]["FrictionResponse"]
    for name, (unit, _) in physics.OUTPUTS.items():
        assert schema["properties"][name]["description"].endswith(f"[{unit}]"), name


def test_manual_settings_table_is_current():
    from docs_pages import page

    assert settings_table() in page("reference/settings.md"), (
        "the manual's settings table is stale: paste service.settings.settings_table() into "
        "docs/pages/reference/settings.md")


def _is_numeric(schema: dict) -> bool:
    """Whether a schema admits a number or an integer (directly, in a union, or as list items)."""
    if schema.get("type") in ("number", "integer"):
        return True
    if schema.get("type") == "array" and _is_numeric(schema.get("items", {})):
        return True
    return any(_is_numeric(sub) for key in ("anyOf", "oneOf", "allOf") for sub in schema.get(key, []))


def _numeric_properties(schema: dict, where: str):
    """(place, description) of every numeric property in ``schema``, nested objects included."""
    for name, sub in (schema.get("properties") or {}).items():
        if _is_numeric(sub):
            yield f"{where}.{name}", sub.get("description", "")
        for key in ("anyOf", "oneOf", "allOf"):
            for k, member in enumerate(sub.get(key, [])):
                yield from _numeric_properties(member, f"{where}.{name}[{key}{k}]")
        yield from _numeric_properties(sub, f"{where}.{name}")
        yield from _numeric_properties(sub.get("items", {}), f"{where}.{name}[]")


def test_every_numeric_field_states_its_unit(spec):
    unit = re.compile(r"\[[^\]]+\]")
    places = [place for name, schema in spec["components"]["schemas"].items()
              for place in _numeric_properties(schema, name)]
    places += [(f"{method} {path} {parameter['name']}", parameter.get("description", ""))
               for path, item in spec["paths"].items() for method, operation in item.items()
               for parameter in operation.get("parameters", []) if _is_numeric(parameter.get("schema", {}))]
    assert len(places) > 100  # the walk reaches the fields (every physics input and output is numeric)
    missing = [place for place, description in places if not unit.search(description)]
    assert not missing, f"numeric fields without a [unit] in their description: {missing}"


def test_schema_names_and_titles_are_unique_after_the_generators_folding(spec):
    # openapi-python-client names a model class by the schema's key, pascal-cased, and an attribute by the
    # property name, snake-cased: two schemas (or two fields of one) that fold alike lose one of them.
    from openapi_python_client.strings import ClassName, PythonIdentifier

    schemas = spec["components"]["schemas"]
    titles = [schema.get("title", name) for name, schema in schemas.items()]
    assert len(set(titles)) == len(titles), sorted(t for t in titles if titles.count(t) > 1)
    assert all(schema.get("title", name) == name for name, schema in schemas.items()), (
        "a schema key differs from its title (pydantic splits a model into -Input/-Output when two "
        "share a name)")
    classes = [ClassName(name, "") for name in schemas]
    assert len(set(classes)) == len(classes), sorted(c for c in classes if classes.count(c) > 1)
    for name, schema in schemas.items():
        fields = [PythonIdentifier(field, "") for field in schema.get("properties", {})]
        assert len(set(fields)) == len(fields), (name, fields)


def test_readme_explains_every_folded_unit_suffix(spec):
    # Generated clients fold load_N to load_n and ball_ball_moment_Nm to ball_ball_moment_nm: the manual's
    # table says what each folded unit suffix means, so _nm is not read as nanometres.
    from openapi_python_client.strings import PythonIdentifier

    names = {field for schema in spec["components"]["schemas"].values()
             for field in schema.get("properties", {})}
    suffixes = set()
    for name in names:
        folded = PythonIdentifier(name, "")
        if folded != name and not folded.endswith("_"):
            stem = name.rstrip("_")
            unit_start = next(i for i, c in enumerate(stem)
                              if c.isupper() or (c.isdigit() and stem[i - 1] == "_"))
            suffixes.add(PythonIdentifier(name[unit_start:], ""))
    from docs_pages import page

    reference = page("reference/rest-api.md")
    missing = sorted(s for s in suffixes if f"| `_{s}` |" not in reference)
    assert suffixes and not missing, f"the REST API reference's table of folded unit suffixes lacks {missing}"


def _unit_suffix(name: str) -> str:
    """The unit part of a field name: from its first capital, or from a digit after "_" (``_1_Pa``)."""
    stem = name.rstrip("_")
    return name[next(i for i, c in enumerate(stem) if c.isupper() or (c.isdigit() and stem[i - 1] == "_")):]


def test_no_generated_name_reads_as_another_unit(spec):
    # Folding turns a unit symbol into another when the lower-case letters spell a prefixed unit:
    # _Nm (newton metre) becomes _nm (nanometre). Every such field must stand beside an alias that
    # survives folding unchanged and carries the same meaning (docs/pages/reference/rest-api.md, "Field
    # names in generated clients").
    from openapi_python_client.strings import PythonIdentifier

    from microbearing.service.schemas.base import FOLDING_SAFE_NAMES

    prefixes, units = "pnumcdkMG", ["m", "g", "s", "N", "Pa", "J", "W", "Hz", "K"]
    symbols = {prefix + unit for prefix in prefixes for unit in units}
    folded_symbols = {symbol.lower() for symbol in symbols}
    misread = []
    for schema_name, schema in spec["components"]["schemas"].items():
        fields = schema.get("properties", {})
        for name in fields:
            if not any(c.isupper() for c in name):
                continue  # no case to lose
            cased = _unit_suffix(name).strip("_").split("_")
            if any(token.lower() in folded_symbols and token not in symbols for token in cased):
                alias = FOLDING_SAFE_NAMES.get(name)
                if alias is None or alias not in fields or PythonIdentifier(alias, "") != alias:
                    misread.append(f"{schema_name}.{name}")
    assert FOLDING_SAFE_NAMES and not misread, f"fields whose generated name reads as another unit: {misread}"


def test_every_job_kind_has_a_typed_result():
    from microbearing.service.schemas.jobs import JOB_RESULTS

    root = SPEC_PATH.parent.parent / "service"
    kinds = set()
    for path in root.rglob("*.py"):
        text = path.read_text(encoding="utf-8")
        kinds |= set(re.findall(r"jobs\.submit\(\s*\"(\w+)\"", text))
        kinds |= set(re.findall(r"^_KIND = \"(\w+)\"", text, flags=re.M))
    assert "sweep" in kinds and kinds <= set(JOB_RESULTS), sorted(kinds - set(JOB_RESULTS))
