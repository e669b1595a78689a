"""docker-compose.yml is valid, passes only settings the server has, and documents its secrets.

Images cannot be pulled on these machines, so the stack is not started here; the same topology
runs natively in test_proxy.py (nginx with the very server block the compose file mounts).
"""

from __future__ import annotations

import ipaddress
import re
import shutil
import subprocess
from pathlib import Path
from typing import Any

import pytest
import yaml

from asset_agent.config import AgentConfig
from assetlink.configfile_cli import PASSWORD_ENV
from base_station.config import load_config as load_station_config
from server.config import Settings
from tests.conftest import IN_CI
from tests.deploy.conftest import conf_relay_ports

ROOT = Path(__file__).resolve().parents[2]
COMPOSE = ROOT / "docker-compose.yml"
ENV_EXAMPLE = ROOT / ".env.example"
# read by other programs in the image, not by server/config.py
NOT_OURS: set[str] = set()


def compose() -> dict[str, Any]:
    return yaml.safe_load(COMPOSE.read_text())  # type: ignore[no-any-return]


def example_env() -> dict[str, str]:
    pairs = (
        line.split("=", 1)
        for line in ENV_EXAMPLE.read_text().splitlines()
        if line.strip() and not line.startswith("#")
    )
    return {k.strip(): v.strip() for k, v in pairs}


def docker_compose() -> str:
    found = shutil.which("docker-compose")
    if found is None:
        message = "docker-compose is not installed (Debian's docker-compose package)"
        if IN_CI:
            pytest.fail(f"{message}; CI=true: .ci/run installs it")
        pytest.skip(f"{message}; in CI this fails instead")
    return found


def run_config(env: dict[str, str], *options: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [
            docker_compose(),
            "--project-directory",
            str(ROOT),
            "-f",
            str(COMPOSE),
            *options,
            "config",
            "-q",
        ],
        env={"PATH": "/usr/bin:/bin", **env},
        capture_output=True,
        text=True,
        timeout=60,
    )


def filled(env: dict[str, str]) -> dict[str, str]:
    """.env.example with every empty (required) value set, as an operator would."""
    return {k: v or f"not-a-real-{k.lower()}" for k, v in env.items()}


def test_docker_compose_accepts_the_file_with_the_example_env_filled_in():
    r = run_config(filled(example_env()))
    assert r.returncode == 0, r.stderr


def test_docker_compose_accepts_the_demo_profile():
    r = run_config(filled(example_env()), "--profile", "demo")
    assert r.returncode == 0, r.stderr


def test_docker_compose_refuses_to_start_without_a_database_password():
    env = filled(example_env())
    del env["POSTGRES_PASSWORD"]
    r = run_config(env)
    assert r.returncode != 0 and "set POSTGRES_PASSWORD in .env" in r.stderr


def test_every_variable_the_compose_file_reads_is_documented_in_env_example_and_back():
    used = set(re.findall(r"\$\{([A-Z0-9_]+)", COMPOSE.read_text()))
    assert used == set(example_env())


def _settings_names() -> set[str]:
    names = set()
    prefix = Settings.model_config.get("env_prefix", "")
    for name, field in Settings.model_fields.items():
        names.add(f"{prefix}{name}".upper())
        choices = getattr(field.validation_alias, "choices", None) or []
        names.update(str(c).upper() for c in choices)
    return names


def test_every_setting_passed_to_a_server_exists_in_the_settings_class():
    services = compose()["services"]
    ours = {
        n: s
        for n, s in services.items()
        if s.get("image", "").startswith("aerobase:") and s["command"][0] in ("server", "admin")
    }
    assert {"server-1", "server-2", "migrate"} == set(ours)
    known = _settings_names()
    for name, service in ours.items():
        unknown = set(service.get("environment", {})) - known - NOT_OURS
        assert not unknown, f"{name} passes settings server/config.py does not have: {unknown}"


def test_the_proxy_mounts_the_server_block_the_native_topology_runs_and_points_at_both_replicas():
    proxy = compose()["services"]["proxy"]
    mounts = {m.split(":")[0]: m.split(":")[1] for m in proxy["volumes"]}
    assert mounts["./deploy/nginx/aerobase.conf"].startswith("/etc/nginx/conf.d/")
    assert mounts["./deploy/nginx/compose"] == "/etc/nginx/aerobase"
    upstream = (ROOT / "deploy" / "nginx" / "compose" / "upstream.conf").read_text()
    assert re.findall(r"^server (\S+):8000", upstream, re.M) == ["server-1", "server-2"]
    # NTRIP's TCP: the stream context the native test runs, in the nginx.conf mounted over the
    # image's, to each replica's caster port
    assert mounts["./deploy/nginx/ntrip.conf"] == "/etc/nginx/ntrip.conf"
    assert mounts["./deploy/nginx/nginx.conf"] == "/etc/nginx/nginx.conf"
    main = (ROOT / "deploy" / "nginx" / "nginx.conf").read_text()
    assert re.search(r"^stream \{\s*include ntrip\.conf;\s*\}", main, re.M)
    assert re.search(r"^http \{[^}]*include conf\.d/\*\.conf;", main, re.M)
    ntrip = (ROOT / "deploy" / "nginx" / "compose" / "ntrip-upstream.conf").read_text()
    port = compose()["services"]["server-1"]["environment"]["AEROBASE_NTRIP_PORT"]
    assert re.findall(rf"^server (\S+):{port} ", ntrip, re.M) == ["server-1", "server-2"]
    assert any(p.endswith(":2101") for p in proxy["ports"])
    # the replicas read the rover's address from the PROXY line the stream proxy sends
    assert "proxy_protocol on;" in (ROOT / "deploy" / "nginx" / "ntrip.conf").read_text()
    assert (
        compose()["services"]["server-1"]["environment"]["AEROBASE_NTRIP_PROXY_PROTOCOL"] == "true"
    )


def test_the_replicas_believe_forwarded_addresses_from_the_proxy_alone():
    """X-Forwarded-For from the proxy's fixed address only, one outside the range the other
    containers' addresses come from; the proxy overwrites it (tests/deploy/test_proxy_trust.py
    runs that nginx)."""
    services = compose()["services"]
    proxy_ip = services["proxy"]["networks"]["default"]["ipv4_address"]
    ipam = compose()["networks"]["default"]["ipam"]["config"][0]
    address = ipaddress.ip_address(proxy_ip)
    assert address in ipaddress.ip_network(ipam["subnet"])
    assert address not in ipaddress.ip_network(ipam["ip_range"])
    for name in ("server-1", "server-2"):
        env = services[name]["environment"]
        assert "FORWARDED_ALLOW_IPS" not in env
        assert env["AEROBASE_FORWARDED_ALLOW_IPS"] == proxy_ip
        assert Settings(environment="production", forwarded_allow_ips=proxy_ip)
    with pytest.raises(ValueError, match="not \\*"):
        Settings(environment="production", forwarded_allow_ips="*")


def test_the_replicas_wait_for_the_migration_and_do_not_migrate_themselves():
    services = compose()["services"]
    for name in ("server-1", "server-2"):
        s = services[name]
        assert s["depends_on"]["migrate"]["condition"] == "service_completed_successfully"
        assert s["environment"]["AEROBASE_MIGRATE_ON_START"] == "false"
    assert services["migrate"]["command"] == ["admin", "migrate"]


def _mounts(service: dict[str, Any]) -> dict[str, str]:
    return {m.split(":")[1]: m.split(":")[0] for m in service.get("volumes", [])}


def test_the_demo_profile_runs_the_world_and_both_daemons_on_configurations_they_accept():
    services = compose()["services"]
    demo = {n for n, s in services.items() if "demo" in s.get("profiles", [])}
    assert demo == {"sim-world", "base-station", "agent"}
    assert services["sim-world"]["command"][:2] == ["sim", "world"]
    for name, load in (
        ("base-station", load_station_config),
        ("agent", AgentConfig.load),
    ):
        service = services[name]
        # the daemons read TOML, not the server's settings: the one variable is the asset password
        assert set(service["environment"]) == {PASSWORD_ENV}
        config_path = service["command"][service["command"].index("--config") + 1]
        config = load(ROOT / _mounts(service)[config_path])
        # every address is the stack's: the simulated world, the server through the proxy
        assert config.server.url == "http://proxy:8080"
        assert _mounts(service)["/run/aerobase"] == "./deploy/demo/assets"
        assert str(config.server.config_file).startswith("/run/aerobase/")
        # its own /metrics on the stack's network, never published on the host
        assert config.metrics.port and "ports" not in service
    base = load_station_config(ROOT / "deploy" / "demo" / "base.toml")
    assert base.plc.host == base.rtk.tcp_host == "sim-world"
    assert AgentConfig.load(ROOT / "deploy" / "demo" / "agent.toml").autopilot.url.startswith(
        "tcp:sim-world:"
    )


def test_janus_and_coturn_mount_the_configurations_the_media_tests_run():
    services = compose()["services"]
    assert _mounts(services["janus"])["/etc/aerobase/janus"] == "./deploy/janus"
    turn = services["coturn"]
    assert _mounts(turn)["/etc/aerobase/turnserver.conf"] == "./deploy/coturn/turnserver.conf"
    # the shared secret comes from .env on the command line, never from a committed file
    assert "--static-auth-secret=${TURN_SECRET:?set TURN_SECRET in .env}" in turn["command"]
    # the relay ports coturn is told are the ones published, by default turnserver.conf's
    conf_low, conf_high = conf_relay_ports()
    low, high = f"${{TURN_MIN_PORT:-{conf_low}}}", f"${{TURN_MAX_PORT:-{conf_high}}}"
    assert {f"--min-port={low}", f"--max-port={high}"} <= set(turn["command"])
    assert f"{low}-{high}:{low}-{high}/udp" in turn["ports"]
    env = example_env()
    assert (env["TURN_MIN_PORT"], env["TURN_MAX_PORT"]) == (str(conf_low), str(conf_high))
