"""The gateway's credentials come from the environment; TLS with a CA file."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import anyio
import pytest

from aiofins.gateway import Gateway, LinkState
from aiofins.gateway.config import parse_config
from aiofins.simulator import VirtualPLC, run_simulator

from .conftest import HANG, Broker, eventually, need_mosquitto

pytestmark = pytest.mark.anyio


def gateway_config(broker: Broker, url: str, mqtt: str = "") -> str:
    return f"""
[mqtt]
port = {broker.port}
backoff_min = 0.05
backoff_max = 0.1
timeout = 2
{mqtt}
[http]
enabled = false
[[groups]]
name = "g"
interval = 0.05
tags = {{ x = "D0" }}
[[plcs]]
name = "p"
url = "{url}"
"""


async def start(broker: Broker) -> None:
    await anyio.to_thread.run_sync(broker.start)


async def test_credentials_from_the_environment(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    need_mosquitto()
    passwords = tmp_path / "passwords"
    subprocess.run(["mosquitto_passwd", "-b", "-c", str(passwords), "gw", "s3cret"], check=True)
    broker = Broker(tmp_path, settings=["allow_anonymous false", f"password_file {passwords}"])
    await start(broker)
    try:
        async with run_simulator(VirtualPLC(), udp=("127.0.0.1", 0)) as sim:
            cfg = parse_config(gateway_config(broker, f"udp://127.0.0.1:{sim.udp_port}"))
            monkeypatch.setenv("AIOFINS_MQTT_USERNAME", "gw")
            monkeypatch.setenv("AIOFINS_MQTT_PASSWORD", "wrong")
            async with Gateway(cfg) as refused:
                await eventually(lambda: refused.link.connect_failures >= 2)
                assert refused.link.state is not LinkState.CONNECTED
                assert refused.link.connects == 0
            monkeypatch.setenv("AIOFINS_MQTT_PASSWORD", "s3cret")
            async with Gateway(cfg) as gateway:
                with anyio.fail_after(HANG):
                    await gateway.link.connected.wait()
                await eventually(lambda: gateway.routes["p/g"].outbox.published >= 2)
    finally:
        broker.stop()


async def test_tls_with_a_ca_file(tmp_path: Path) -> None:
    need_mosquitto()
    if shutil.which("openssl") is None:
        pytest.skip("openssl is not installed")
    ca_key, ca, key, csr, cert = (
        tmp_path / n for n in ("ca.key", "ca.pem", "s.key", "s.csr", "s.pem")
    )

    def openssl(*args: str) -> None:
        subprocess.run(["openssl", *args], check=True, capture_output=True)

    openssl(
        "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "1", "-subj", "/CN=test CA",
        "-keyout", str(ca_key), "-out", str(ca),
    )  # fmt: skip
    openssl(
        "req", "-newkey", "rsa:2048", "-nodes", "-subj", "/CN=127.0.0.1",
        "-keyout", str(key), "-out", str(csr),
    )  # fmt: skip
    ext = tmp_path / "ext.cnf"
    ext.write_text("subjectAltName = IP:127.0.0.1\n")
    openssl(
        "x509", "-req", "-in", str(csr), "-CA", str(ca), "-CAkey", str(ca_key),
        "-CAcreateserial", "-days", "1", "-extfile", str(ext), "-out", str(cert),
    )  # fmt: skip
    broker = Broker(
        tmp_path,
        settings=["allow_anonymous true", f"cafile {ca}", f"certfile {cert}", f"keyfile {key}"],
    )
    await start(broker)
    try:
        async with run_simulator(VirtualPLC(), udp=("127.0.0.1", 0)) as sim:
            url = f"udp://127.0.0.1:{sim.udp_port}"
            cfg = parse_config(gateway_config(broker, url, f'tls = true\nca_file = "{ca}"'))
            async with Gateway(cfg) as gateway:
                with anyio.fail_after(HANG):
                    await gateway.link.connected.wait()
                await eventually(lambda: gateway.routes["p/g"].outbox.published >= 2)
            # Without the CA the broker's certificate is not trusted: no connection.
            untrusted = parse_config(gateway_config(broker, url, "tls = true"))
            async with Gateway(untrusted) as refused:
                await eventually(lambda: refused.link.connect_failures >= 1)
                assert refused.link.connects == 0
    finally:
        broker.stop()
