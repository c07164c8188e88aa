"""Long lists of numbers of a large batch body read straight into arrays (service.schemas.number_lists).

The arrays must hold exactly what the JSON parser reads, every body the plain parse refuses must still be
refused (as malformed, or by the schema naming the element), and a batch must answer as its small self.
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pydantic_core import from_json

from microbearing import physics
from microbearing.service.schemas import number_lists

#: Points of a batch long enough (with 17 significant digits a number) to pass the 4 MiB of lifting.
COUNT = 240_000


def numbers_text(values: np.ndarray) -> str:
    return ", ".join(repr(float(v)) for v in values)


def lifted_values(text: str) -> np.ndarray | None:
    lifted = number_lists.lift_number_lists(f'{{"x": {{"c": [{text}]}}}}'.encode())
    if lifted is None:
        return None
    document = number_lists.place_arrays(lifted, {"x"})
    return None if document is None else document["x"]["c"]


@pytest.fixture(scope="module")
def long_values() -> np.ndarray:
    rng = np.random.default_rng(7)
    # numbers of every form JSON writes: integers, fractions, exponents, signs
    return np.concatenate([rng.lognormal(-3, 4, 20_000), -rng.random(10_000), np.arange(-500.0, 500.0)])


def test_a_long_list_is_read_as_the_json_parser_reads_it(long_values):
    text = numbers_text(long_values) + ", 12, -0, 1E-7, 3e+2, 123456789012345678901234567890"
    assert len(text) > number_lists.MIN_LIST_BYTES
    read = lifted_values(text)
    assert read is not None and read.dtype == np.float64
    np.testing.assert_array_equal(read, np.asarray(from_json(f"[{text}]"), dtype=float))  # bit for bit


@pytest.mark.parametrize("change", [
    lambda t: t + ",",  # a trailing comma
    lambda t: t + ",   \n",
    lambda t: ", " + t,  # a leading one
    lambda t: t.replace(", ", ", , ", 1),  # an empty element
    lambda t: t.replace(", ", " ", 1),  # a missing comma
    lambda t: t + ", +1",  # not JSON numbers, though C's strtod reads them
    lambda t: t + ", .5",
    lambda t: t + ", 1.",
    lambda t: t + ", 01",
    lambda t: t + ", 1e",
])
def test_a_list_the_json_parser_refuses_is_left_to_it(long_values, change):
    text = change(numbers_text(long_values))
    with pytest.raises(ValueError):
        from_json(f"[{text}]")
    assert lifted_values(text) is None  # not lifted: the plain parse refuses the body


def test_a_list_cut_into_pieces_at_every_place_reads_whole(monkeypatch):
    monkeypatch.setattr(number_lists, "_PIECE_BYTES", 7)  # cuts inside and between numbers
    values = np.linspace(-2.0, 3.0, 41)
    for text in (numbers_text(values), numbers_text(values).replace(", ", " ,\n ")):
        np.testing.assert_array_equal(number_lists._numbers(text.encode()), values)
        assert number_lists._numbers((text + ",").encode()) is None
        assert number_lists._numbers((text + ", ").encode()) is None


def test_non_finite_numbers_are_read_for_the_schema_to_refuse(long_values):
    read = lifted_values(numbers_text(long_values) + ", NaN, Infinity, -Infinity")
    assert np.isnan(read[-3]) and read[-2] == np.inf and read[-1] == -np.inf


def test_a_list_inside_a_string_or_in_a_key_is_never_lifted(long_values):
    text = numbers_text(long_values)
    inside = f'{{"name": "a [{text}] b", "x": [{text}]}}'.encode()
    lifted = number_lists.lift_number_lists(inside)
    assert lifted is not None  # the regular expression sees both lists...
    assert number_lists.place_arrays(lifted, {"x"}) is None  # ...and the skeleton says one is in a string
    as_key = f'{{[{text}]: 1}}'.encode()  # not JSON: a list where a key belongs
    assert number_lists.place_arrays(number_lists.lift_number_lists(as_key), {"x"}) is None


def test_arrays_go_where_the_fields_take_them_and_lists_elsewhere(long_values):
    text = numbers_text(long_values)
    body = f'{{"points": {{"load_N": [{text}]}}, "other": {{"deep": [[{text}]]}}, "list": [{text}]}}'
    document = number_lists.place_arrays(number_lists.lift_number_lists(body.encode()), {"points"})
    assert isinstance(document["points"]["load_N"], np.ndarray)
    assert isinstance(document["other"]["deep"][0], list) and isinstance(document["list"], list)
    assert document["list"] == json.loads(f"[{text}]")


def post(client, points: dict, count_check: bool = True, **fields):
    body = json.dumps({"points": points, "outputs": ["mu"], **fields})
    if count_check:
        assert len(body) > 4 * 2**20, "the body must be large enough to be lifted"
    return client.post("/v1/friction/batch", content=body, headers={"content-type": "application/json"})


def test_a_large_batch_answers_as_the_physics_does(client, monkeypatch):
    from microbearing.service.schemas import base

    validated = []
    monkeypatch.setattr(base, "_validate_lifted", lambda model, document: validated.append(document) or
                        model.model_validate(document))
    loads = np.random.default_rng(3).uniform(1e-3, 2e-2, COUNT)
    speeds = np.random.default_rng(4).uniform(1e-3, 0.2, COUNT)
    response = post(client, {"balls": 6, "load_N": loads.tolist(), "speed_m_s": speeds.tolist()})
    assert response.status_code == 200, response.text[:300]
    assert isinstance(validated[0]["points"]["load_N"], np.ndarray)  # read as arrays, never as floats
    expected = physics.evaluate(balls=6, load_N=loads, speed_m_s=speeds).mu
    np.testing.assert_allclose(response.json()["mu"], expected, rtol=1e-12)


def test_a_large_column_sent_in_other_units_is_converted(client):
    loads_mN = np.random.default_rng(5).uniform(1.0, 20.0, COUNT)
    response = post(client, {"balls": 4, "load [mN]": loads_mN.tolist(), "speed_m_s": 0.05})
    assert response.status_code == 200, response.text[:300]
    expected = physics.evaluate(balls=4, load_N=loads_mN / 1000, speed_m_s=0.05).mu
    np.testing.assert_allclose(response.json()["mu"], expected, rtol=1e-12)


def test_bad_elements_of_a_large_column_are_named_as_a_small_one_names_them(client):
    loads = np.full(COUNT, 0.012345678901234567)
    loads[[17, 200_001]] = [-0.5, 0.0]
    large = post(client, {"balls": 4, "load_N": loads.tolist(), "speed_m_s": 0.05})
    small = post(client, {"balls": 4, "load_N": [0.01] * 17 + [-0.5, 0.0], "speed_m_s": 0.05},
                 count_check=False)
    assert large.status_code == small.status_code == 422
    assert large.headers["content-type"] == "application/problem+json"
    pointers = [error["pointer"] for error in large.json()["errors"]]
    assert pointers == ["/points/load_N/17", "/points/load_N/200001"]
    assert [e["detail"] for e in large.json()["errors"]] == [e["detail"] for e in small.json()["errors"]]


def test_a_fraction_among_ball_counts_and_a_number_for_a_flag_are_refused(client):
    balls = [4.000000000000000] * COUNT
    balls[9] = 4.5
    response = post(client, {"balls": balls, "load_N": [0.012345678901234567] * COUNT, "speed_m_s": 0.05})
    assert response.status_code == 422
    assert [e["pointer"] for e in response.json()["errors"]] == ["/points/balls/9"]
    flags = [1] * COUNT
    response = post(client, {"balls": 4, "load_N": [0.012345678901234567] * COUNT, "balls_touching": flags,
                             "speed_m_s": 0.05})
    errors = response.json()["errors"]
    assert response.status_code == 422 and errors[0]["pointer"] == "/points/balls_touching/0", errors[:2]
    assert len(errors) <= number_lists.MAX_ERRORS_PER_COLUMN


def test_large_refusals_of_shape_and_grammar_stay_as_they_were(client):
    loads = [0.012345678901234567] * COUNT
    unknown = post(client, {"balls": 4, "load_N": loads, "speed_m_s": 0.05, "ball_radius_m": loads})
    assert unknown.status_code == 422
    assert [e["pointer"] for e in unknown.json()["errors"]] == ["/points/ball_radius_m"]
    lengths = post(client, {"balls": 4, "load_N": loads, "speed_m_s": loads[:-1]})
    assert lengths.status_code == 422 and lengths.json()["errors"][0]["pointer"] == "/points/speed_m_s"
    body = json.dumps({"points": {"balls": 4, "load_N": loads, "speed_m_s": 0.05}})
    malformed = client.post("/v1/friction/batch", content=body.replace("]", ", ]"),
                            headers={"content-type": "application/json"})
    assert malformed.status_code == 400 and malformed.json()["title"] == "Malformed JSON"


# Any JSON document, with every list of numbers short enough to be lifted: the lifted document is the parsed
# one (arrays as lists), or None when the plain parse must answer; never another document.
_NUMBERS = st.one_of(st.integers(-10**6, 10**6), st.floats(allow_nan=False, allow_infinity=False, width=64))
_LEAVES = st.one_of(_NUMBERS, st.booleans(), st.none(),
                    st.text(alphabet=st.sampled_from('ab[]{}",:\\ 0123456789.-eE'), max_size=12))
_DOCUMENTS = st.recursive(
    _LEAVES,
    lambda inner: st.one_of(st.lists(inner, max_size=5), st.lists(_NUMBERS, min_size=1, max_size=12),
                            st.dictionaries(st.text(alphabet="abc[] 0,", max_size=4), inner, max_size=4)),
    max_leaves=30)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(document=_DOCUMENTS, indent=st.sampled_from([None, 1]))
def test_a_lifted_document_is_the_parsed_document_or_none(monkeypatch, document, indent):
    monkeypatch.setattr(number_lists, "_NUMBER_LIST", re.compile(rb"\[([-+0-9.eE,\s NaIfinity]{1,})\]"))
    monkeypatch.setattr(number_lists, "_PIECE_BYTES", 5)
    body = json.dumps({"points": document, "other": document}, indent=indent).encode()
    lifted = number_lists.lift_number_lists(body)
    if lifted is None:
        return
    placed = number_lists.place_arrays(lifted, {"points"})
    if placed is None:
        return

    def plain(value):
        if isinstance(value, np.ndarray):
            return [float(v) for v in value]
        if isinstance(value, list):
            return [plain(v) for v in value]
        if isinstance(value, dict):
            return {k: plain(v) for k, v in value.items()}
        return float(value) if isinstance(value, int | float) and not isinstance(value, bool) else value

    assert plain(placed) == plain(json.loads(body))
