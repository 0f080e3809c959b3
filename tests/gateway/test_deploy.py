"""deploy/ run for real: deploy/Dockerfile's image, and deploy/docker-compose.yml's Mosquitto,
three virtual PLCs and two gateway shards, watched by an MQTT subscriber on the host.

Needs a Docker daemon, Debian's ``docker-compose`` and (once) a Debian host's ``apt-get`` and
``dpkg-deb``: public images cannot be pulled here, so both images are built on
deploy/debian-base.sh's Debian root.
.ci/run installs them, starts the daemon and sets ``AIOFINS_DOCKER_REQUIRED``: then anything
missing fails the test; without it, the test skips saying what is missing.

Every wait is a bounded wait for messages the subscriber received; nothing is timed.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from collections.abc import AsyncIterator, Callable, Iterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any, NoReturn

import aiomqtt
import anyio
import pytest

import aiofins
from aiofins.gateway import Shard, load_config
from aiofins.gateway.config import render

from .conftest import Subscriber, subscribe

ROOT = Path(__file__).resolve().parents[2]
DEPLOY = ROOT / "deploy"
#: Set by .ci/run once its daemon answers: a missing piece is then a failure, not a skip.
REQUIRED = bool(os.environ.get("AIOFINS_DOCKER_REQUIRED"))
#: The bound of every wait for the stack (a bound, not a target: CI may be busy).
WAIT = 180.0
#: The gateway image adds its virtual environment to the base, nothing else (no source tree,
#: no pip, no build cache): about 6 MB.
IMAGE_GROWTH_LIMIT = 20_000_000
#: What .dockerignore lets into the build context: what deploy/Dockerfile copies.
CONTEXT = {"LICENSE", "README.md", "pyproject.toml", "src"}


@pytest.fixture
def anyio_backend() -> str:
    return "asyncio"  # the stack runs in containers: one loop for the subscriber is enough


def unavailable(reason: str) -> NoReturn:
    if REQUIRED:
        pytest.fail(f"{reason} (AIOFINS_DOCKER_REQUIRED is set: .ci/run started a daemon)")
    pytest.skip(reason)


def run(*args: str, env: dict[str, str] | None = None, stdin: str | None = None) -> str:
    """A command's stdout; a failure raises with its stderr."""
    done = subprocess.run(
        args, input=stdin, capture_output=True, text=True, env=env, cwd=ROOT, timeout=900
    )
    if done.returncode != 0:
        raise AssertionError(f"{' '.join(args)}: exit {done.returncode}\n{done.stderr[-4000:]}")
    return done.stdout


@pytest.fixture
def base_image() -> str:
    """deploy/debian-base.sh's image (made on first use), or a skip saying what is missing."""
    if shutil.which("docker") is None:
        unavailable("docker is not installed (apt-get install docker.io)")
    info = subprocess.run(
        ["docker", "info", "--format", "{{.ServerVersion}}"], capture_output=True, text=True
    )
    if info.returncode != 0:
        last = (info.stderr.strip().splitlines() or ["?"])[-1]
        unavailable(f"no Docker daemon answers ({last}); .ci/run starts one")
    if shutil.which("docker-compose") is None:
        unavailable("docker-compose is not installed (apt-get install docker-compose)")
    image = os.environ.get("AIOFINS_BASE_IMAGE", "aiofins-debian:bookworm")
    exists = subprocess.run(["docker", "image", "inspect", image], capture_output=True)
    if exists.returncode != 0:
        if shutil.which("apt-get") is None or shutil.which("dpkg-deb") is None:
            unavailable(f"no base image {image}, and no apt-get and dpkg-deb to make it (Debian)")
        if os.geteuid() != 0:
            unavailable(f"no base image {image}; as root, deploy/debian-base.sh makes it")
    return run("bash", str(DEPLOY / "debian-base.sh")).strip()


PROJECT = "aiofinsdeploytest"


class Stack:
    """deploy/docker-compose.yml as a compose project of its own (named after the test's
    process), on host ports Docker picks."""

    def __init__(self, base: str, pid: int) -> None:
        self.project = f"{PROJECT}{pid}"
        self.image = f"aiofins-gateway:test-{pid}"
        self.env = {
            **os.environ,
            "AIOFINS_PYTHON_IMAGE": base,
            "AIOFINS_MOSQUITTO_IMAGE": base,
            "AIOFINS_IMAGE": self.image,
            "AIOFINS_MQTT_PUBLISH": "127.0.0.1:",
            "AIOFINS_METRICS_PUBLISH_0": "127.0.0.1:",
            "AIOFINS_METRICS_PUBLISH_1": "127.0.0.1:",
            "DOCKER_BUILDKIT": "0",  # Debian's docker.io: the classic builder
        }

    def compose(self, *args: str) -> str:
        return run(
            "docker-compose",
            "--project-name",
            self.project,
            "--file",
            str(DEPLOY / "docker-compose.yml"),
            *args,
            env=self.env,
        )

    def logs(self) -> str:
        try:
            return self.compose("logs", "--no-color", "--tail", "40")
        except AssertionError as exc:
            return str(exc)

    def down(self) -> None:
        self.compose("down", "--volumes", "--remove-orphans", "--timeout", "10")
        subprocess.run(["docker", "rmi", self.image], capture_output=True)


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass
    return True


def sweep(base: str) -> None:
    """Takes down the stacks of earlier runs killed before their clean-up: their containers
    would start again with every start of the daemon (``restart: unless-stopped``)."""
    projects = run(
        "docker", "ps", "--all", "--format", '{{.Label "com.docker.compose.project"}}'
    )  # fmt: skip
    for project in set(projects.split()):
        pid = project.removeprefix(PROJECT)
        if project.startswith(PROJECT) and pid.isdigit() and not alive(int(pid)):
            Stack(base, int(pid)).down()


@pytest.fixture
def stack(base_image: str) -> Iterator[Stack]:
    sweep(base_image)
    s = Stack(base_image, os.getpid())
    try:
        yield s
    finally:
        s.down()


def image_size(image: str) -> int:
    return int(run("docker", "image", "inspect", "--format", "{{.Size}}", image))


def build_context(base: str, tag: str) -> set[str]:
    """The build context's top level as the daemon receives it (.dockerignore applied), and
    whatever caches slipped in below it."""
    run(
        "docker",
        "build",
        "--quiet",
        "--tag",
        tag,
        "--file",
        "-",
        ".",
        stdin=(f"FROM {base}\nCOPY . /context\n"),
        env={**os.environ, "DOCKER_BUILDKIT": "0"},
    )
    try:
        listing = run(
            "docker", "run", "--rm", tag, "sh", "-c",
            "cd /context && ls -A && find . -name __pycache__ -o -name '*.egg-info'",
        )  # fmt: skip
    finally:
        subprocess.run(["docker", "rmi", tag], capture_output=True)
    return set(listing.split())


@asynccontextmanager
async def subscriber(port: int) -> AsyncIterator[Subscriber]:
    """A subscriber to ``fins/#``, once the broker answers MQTT (a bounded poll: Docker's
    port forwarder accepts TCP before the broker in the container listens)."""
    with anyio.fail_after(WAIT):
        while True:
            try:
                async with aiomqtt.Client("127.0.0.1", port, timeout=5):
                    break
            except aiomqtt.MqttError:
                await anyio.sleep(0.2)  # the broker's container is still starting
    async with subscribe(port, "fins/#") as sub:
        yield sub


def after(sub: Subscriber, mark: int, topic: str) -> list[Any]:
    """The JSON payloads on ``topic`` received after the first ``mark`` messages."""
    return [m.json() for m in sub.messages[mark:] if m.topic == topic]


def states(sub: Subscriber, mark: int, topic: str) -> list[str]:
    return [p["state"] for p in after(sub, mark, topic)]


def good_scans(sub: Subscriber, mark: int, topic: str) -> list[int]:
    return [p["scan"] for p in after(sub, mark, topic) if p["error"] is None]


async def until(sub: Subscriber, what: str, condition: Callable[[], object]) -> None:
    try:
        await sub.wait_for(condition, timeout=WAIT)
    except TimeoutError:
        raise AssertionError(f"not within {WAIT:.0f} s: {what}") from None


@pytest.mark.anyio
async def test_compose_stack_publishes_every_plc_once_and_a_killed_shard_recovers(
    stack: Stack,
) -> None:
    config = load_config(DEPLOY / "gateway.toml")
    (group,) = config.groups.values()
    shards = 2
    owner = {
        p.name: f"{config.name}-{i}"
        for i in range(shards)
        for p in config.plcs
        if Shard(i, shards).owns(p.name)
    }
    scan_topic = {p: render(group.topic, plc=p, group=group.name) for p in owner}
    status_topic = {p: render(config.mqtt.plc_status_topic, plc=p) for p in owner}
    gateway_topic = {g: render(config.mqtt.gateway_topic, gateway=g) for g in set(owner.values())}
    assert len(gateway_topic) == shards, f"a shard polls no PLC: {owner}"
    base = stack.env["AIOFINS_PYTHON_IMAGE"]

    # The context holds what the Dockerfile copies: no .venv, .git, site/, caches.
    assert build_context(base, f"{stack.image}-context") == CONTEXT

    # The image: the base plus a virtual environment (multi-stage: no source, no pip).
    stack.compose("build", "gateway-0")
    growth = image_size(stack.image) - image_size(base)
    assert 0 < growth < IMAGE_GROWTH_LIMIT, f"the image adds {growth / 1e6:.1f} MB to its base"
    version = run("docker", "run", "--rm", stack.image, "--version")
    assert version.strip() == f"aiofins {aiofins.__version__}"

    try:
        stack.compose("up", "--detach", "--no-build")
        host, _, port = stack.compose("port", "mosquitto", "1883").strip().rpartition(":")
        assert host == "127.0.0.1"
        async with subscriber(int(port)) as sub:
            # Every shard online; every PLC online and scanned, by the shard that owns it.
            def all_up(mark: int = 0) -> bool:
                return all(
                    states(sub, mark, t)[-1:] == ["online"] for t in gateway_topic.values()
                ) and all(
                    len(good_scans(sub, mark, scan_topic[p])) >= 3
                    and "online" in states(sub, mark, status_topic[p])
                    for p in owner
                )

            await until(sub, "every shard and PLC online, three scans each", all_up)
            for plc, g in owner.items():
                announcers = {s["gateway"] for s in after(sub, 0, status_topic[plc])}
                assert announcers == {g}, f"{plc} announced by {announcers}"
                scans = [s["scan"] for s in after(sub, 0, scan_topic[plc])]
                assert len(scans) == len(set(scans)), f"{plc} scanned twice: {scans}"

            # Kill the shard with the most PLCs: the broker publishes its last will.
            victim = max(gateway_topic, key=lambda g: (list(owner.values()).count(g), g))
            service = "gateway-" + victim.rpartition("-")[2]
            lost = [p for p, g in owner.items() if g == victim]
            kept = [p for p in owner if p not in lost]
            killed = len(sub.messages)
            stack.compose("kill", service)
            await until(
                sub,
                f"{victim}'s last will",
                lambda: "offline" in states(sub, killed, gateway_topic[victim]),
            )
            will = next(m for m in sub.messages[killed:] if m.topic == gateway_topic[victim])
            assert will.json()["state"] == "offline"
            # The other shard goes on publishing its PLCs meanwhile.
            down = len(sub.messages)
            await until(
                sub,
                "the surviving shard's scans",
                lambda: all(len(good_scans(sub, down, scan_topic[p])) >= 2 for p in kept),
            )

            # Restarted, it says online and publishes its PLCs again.
            stack.compose("start", service)
            await until(
                sub,
                f"{victim} online again",
                lambda: "online" in states(sub, down, gateway_topic[victim]),
            )
            back = next(
                i
                for i, m in enumerate(sub.messages)
                if i >= down and m.topic == gateway_topic[victim] and m.json()["state"] == "online"
            )
            await until(
                sub,
                f"{lost} published again",
                lambda: all(
                    len(good_scans(sub, back, scan_topic[p])) >= 2
                    and "online" in states(sub, back, status_topic[p])
                    for p in lost
                ),
            )
            for plc, g in owner.items():
                announcers = {s["gateway"] for s in after(sub, 0, status_topic[plc])}
                assert announcers == {g}, f"{plc} announced by {announcers}"
    except BaseException:
        print(stack.logs())
        raise
