"""The reverse proxy of the README: ``deploy/nginx/microbearing.conf`` as it is, in front of a live server.

Only the ports are replaced. Through nginx: answers and numbers unchanged (a point, a streamed
batch), the client's address forwarded, nginx's own refusals (a header line too long, a body
declared too large, the service down) answered as problem+json, and a connection that does not
finish its headers closed after the configured 10 s. Skipped when nginx is not installed
(``apt-get install nginx``).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import time

import httpx
import numpy as np
import pytest
from live_server import REPO, free_port
from test_reliability_connections import Serve, partial_head, raw_request

from microbearing import physics

NGINX = shutil.which("nginx") or next((path for path in ("/usr/sbin/nginx", "/usr/local/sbin/nginx")
                                       if os.access(path, os.X_OK)), None)
pytestmark = pytest.mark.skipif(NGINX is None, reason="nginx is not installed")
EXAMPLE = REPO / "deploy" / "nginx" / "microbearing.conf"


@pytest.fixture
def proxied(tmp_path):
    server = Serve(tmp_path)
    port = free_port()
    site = EXAMPLE.read_text().replace("server 127.0.0.1:8000;", f"server 127.0.0.1:{server.port};")
    site = re.sub(r"listen 80;", f"listen 127.0.0.1:{port};", site)
    assert f"127.0.0.1:{server.port}" in site and f"listen 127.0.0.1:{port}" in site
    (tmp_path / "site.conf").write_text(site)
    temp = {name: tmp_path / name for name in ("body", "proxy", "fastcgi", "uwsgi", "scgi")}
    for folder in temp.values():
        folder.mkdir()
    user = "user root;" if os.geteuid() == 0 else ""
    (tmp_path / "nginx.conf").write_text(f"""
{user}
worker_processes 1;
daemon off;
pid {tmp_path}/nginx.pid;
error_log {tmp_path}/error.log info;
events {{ worker_connections 1024; }}
http {{
    access_log {tmp_path}/access.log;
    client_body_temp_path {temp['body']};
    proxy_temp_path {temp['proxy']};
    fastcgi_temp_path {temp['fastcgi']};
    uwsgi_temp_path {temp['uwsgi']};
    scgi_temp_path {temp['scgi']};
    include {tmp_path}/site.conf;
}}
""")
    nginx = subprocess.Popen([NGINX, "-c", str(tmp_path / "nginx.conf"), "-p", str(tmp_path)],
                             stdout=subprocess.DEVNULL, stderr=(tmp_path / "nginx.out").open("wb"))
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 30
        while True:
            try:
                if httpx.get(f"{url}/healthz", timeout=1).status_code == 200:
                    break
            except httpx.TransportError:
                pass
            assert nginx.poll() is None, (tmp_path / "nginx.out").read_text()
            assert time.monotonic() < deadline, (tmp_path / "error.log").read_text()[-2000:]
            time.sleep(0.1)
        yield server, url, port
    finally:
        nginx.terminate()
        nginx.wait(timeout=30)
        server.stop()


def test_the_example_nginx_configuration_in_front_of_a_live_server(proxied):
    server, url, port = proxied
    with httpx.Client(base_url=url, timeout=60) as client:
        point = client.post("/v1/friction", json={"balls": 4, "load_N": 0.0088, "speed_m_s": 0.05})
        assert point.status_code == 200
        assert point.json()["mu"] == physics.evaluate(balls=4, load_N=0.0088, speed_m_s=0.05).mu
        load = np.linspace(1e-3, 0.05, 200_000)
        batch = client.post("/v1/friction/batch", json={"points": {"balls": 6, "load_N": load.tolist(),
                                                                   "speed_m_s": 0.02}, "outputs": ["mu"]})
        assert batch.status_code == 200
        np.testing.assert_array_equal(batch.json()["mu"], physics.evaluate(balls=6, load_N=load,
                                                                            speed_m_s=0.02).mu)
        # The service's own problems pass through unchanged.
        invalid = client.post("/v1/friction", json={"balls": 4, "load_N": -1, "speed_m_s": 0.05})
        assert invalid.status_code == 422 and invalid.headers["content-type"] == "application/problem+json"

        # nginx's refusals, as problems: a header line too long, a body declared too large.
        long_header = client.get("/healthz", headers={"X-Big": "a" * 40_000})
        assert long_header.status_code == 431, long_header.text
        assert long_header.headers["content-type"] == "application/problem+json"
        assert json.loads(long_header.content)["status"] == 431
    too_large = raw_request(port, b"POST /v1/friction/batch HTTP/1.1\r\nHost: a\r\nContent-Type: "
                                  b"application/json\r\nContent-Length: 300000000\r\n\r\n")
    head, _, body = too_large.partition(b"\r\n\r\n")
    assert head.startswith(b"HTTP/1.1 413") and b"application/problem+json" in head, too_large[:300]
    assert json.loads(body)["status"] == 413

    # A connection that never finishes its headers is closed after client_header_timeout (10 s).
    sock = partial_head(port)
    opened = time.monotonic()
    sock.settimeout(30)
    try:
        sock.recv(1)
    except ConnectionResetError:
        pass
    waited = time.monotonic() - opened
    sock.close()
    print(f"nginx closed an unfinished head after {waited:.1f} s")
    assert 9 <= waited <= 20

    # The service down: nginx answers 503 as a problem, with Retry-After.
    server.process.terminate()
    server.process.wait(timeout=30)
    down = httpx.get(f"{url}/healthz", timeout=30)
    assert down.status_code == 503 and down.headers["content-type"] == "application/problem+json"
    assert down.headers["retry-after"] == "5"

