"""Lists in pages: ``GET /v1/calibrations`` and ``GET /v1/surrogates`` page as ``GET /v1/jobs`` does
(``limit``, ``page_token``, ``next_url``), on both stores (SQLite and PostgreSQL: tests/conftest.py)."""

from __future__ import annotations

import random

import pytest
from fastapi.testclient import TestClient
from test_service_resources import bearer, finished

from microbearing.service.app import create_app
from microbearing.service.schemas import examples
from microbearing.service.settings import Settings

ALPHA, BETA = "alpha-key-0123456789", "beta-key-9876543210"
PROBLEM = "application/problem+json"
LISTS = {"/v1/calibrations": "calibrations", "/v1/surrogates": "surrogates"}
SURROGATE = {"space": {"balls": [4, 8]}, "fixed": {"load_N": 0.01, "speed_m_s": 0.05}, "budget": 4,
             "validation_points": 0}
CALIBRATION = examples.CALIBRATION  # 24 rows, 3 folds


def follow(client: TestClient, url: str, key: str, field: str) -> tuple[list[str], int]:
    """Every id of a list by following next_url from ``url``, and the number of pages."""
    ids, pages = [], 0
    while url is not None:
        response = client.get(url, headers=bearer(key))
        assert response.status_code == 200, response.text
        body = response.json()
        ids += [item["id"] for item in body[field]]
        url, pages = body["next_url"], pages + 1
    return ids, pages


@pytest.fixture
def client(database):
    """An app on a new database of each backend, with two API keys."""
    settings = Settings(data_dir=database.folder, api_keys=f"{ALPHA},{BETA}", **database.settings())
    with TestClient(create_app(settings)) as test_client:
        yield test_client


def test_calibrations_and_surrogates_are_listed_a_page_at_a_time_newest_first(client):
    made = {path: [] for path in LISTS}
    for _ in range(5):  # interleaved: each list holds only its own kind
        made["/v1/surrogates"].append(finished(client, client.post("/v1/surrogates", json=SURROGATE,
                                                                    headers=bearer(ALPHA)), ALPHA)["id"])
        made["/v1/calibrations"].append(finished(client, client.post("/v1/calibrations", json=CALIBRATION,
                                                                      headers=bearer(ALPHA)), ALPHA)["id"])
    other = finished(client, client.post("/v1/surrogates", json=SURROGATE, headers=bearer(BETA)), BETA)["id"]
    for path, field in LISTS.items():
        newest_first = made[path][::-1]
        # two per page: 2 + 2 + 1, the last page without next_url
        assert follow(client, f"{path}?limit=2", ALPHA, field) == (newest_first, 3)
        assert follow(client, f"{path}?limit=5", ALPHA, field) == (newest_first, 1)
        assert follow(client, f"{path}?limit=4", ALPHA, field) == (newest_first, 2)
        # the default page holds them all (20), with no next page
        whole = client.get(path, headers=bearer(ALPHA)).json()
        assert [item["id"] for item in whole[field]] == newest_first and whole["next_url"] is None
        first = client.get(path, params={"limit": 2}, headers=bearer(ALPHA)).json()
        assert first["next_url"].startswith(f"{path}?limit=2&page_token=")
        # a key sees only its own: BETA's surrogate is on no page of ALPHA's
        assert other not in follow(client, f"{path}?limit=1", ALPHA, field)[0]
    assert follow(client, "/v1/surrogates?limit=1", BETA, "surrogates") == ([other], 1)
    # a model deleted between two pages is left out, and the next page still starts after the last row
    first = client.get("/v1/surrogates", params={"limit": 2}, headers=bearer(ALPHA)).json()
    gone = client.delete(f"/v1/surrogates/{made['/v1/surrogates'][2]}", headers=bearer(ALPHA))
    assert gone.status_code == 204
    rest, _ = follow(client, first["next_url"], ALPHA, "surrogates")
    assert rest == [made["/v1/surrogates"][1], made["/v1/surrogates"][0]]


@pytest.mark.parametrize("path", list(LISTS))
@pytest.mark.parametrize(("params", "name"), [
    ({"limit": 0}, "limit"), ({"limit": 101}, "limit"), ({"limit": "many"}, "limit"),
    ({"page_token": "not a token"}, "page_token"), ({"page_token": "x" * 129}, "page_token"),
])
def test_bad_page_parameters_are_problems_naming_them(client, path, params, name):
    response = client.get(path, params=params, headers=bearer(ALPHA))
    assert response.status_code == 422 and response.headers["content-type"] == PROBLEM, response.text
    assert [e.get("parameter") for e in response.json()["errors"]] == [name]


def test_the_store_pages_models_in_one_order_ties_included(database):
    # Models created in the same millisecond are ordered by id: the pages then neither skip nor
    # repeat one. Truth: the rows sorted here by (created_at, id), newest first.
    store = database.store()
    rng = random.Random(3)
    times = ["2026-01-01T00:00:00.000Z", "2026-01-01T00:00:00.001Z", "2026-01-02T00:00:00.000Z"]
    rows = [(f"{rng.getrandbits(128):032x}", rng.choice(("surrogate", "calibration")), rng.choice(times))
            for _ in range(23)]
    with store.transaction() as conn:
        for model_id, kind, created_at in rows:
            conn.execute("INSERT INTO models (id, kind, name, metadata_json, arrays_npz, owner_key, "
                         "created_at) VALUES (?, ?, '', '{}', ?, NULL, ?)", (model_id, kind, b"", created_at))
    for kind in ("surrogate", "calibration", None):
        truth = sorted(((c, i) for i, k, c in rows if kind in (None, k)), reverse=True)
        assert [(m["created_at"], m["id"]) for m in store.list_models(kind)] == truth
        for limit in (1, 2, 5, 100):
            seen, before = [], None
            while True:
                page = store.list_models(kind, limit, before)
                assert len(page) <= limit
                seen += [(m["created_at"], m["id"]) for m in page]
                if len(page) < limit:
                    break
                before = seen[-1]
            assert seen == truth, (kind, limit)
