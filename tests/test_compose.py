"""docker-compose.yml, checked without a container engine: against the Compose Specification's
JSON schema, for the wiring the deployment relies on, and for commands that exist.

``tests/data/compose_spec.json`` is the specification's schema as shipped in the PyPI package
docker-compose 1.29.2 (``compose/config/compose_spec.json``, Apache-2.0), vendored unchanged. It
predates the top-level ``name`` (the project name, in the specification since 2022), which is
checked on its own.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

import jsonschema
import pytest
import yaml

from darkread.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]
SCHEMA = Path(__file__).parent / "data" / "compose_spec.json"


@pytest.fixture(scope="module")
def compose() -> dict[str, Any]:
    return yaml.safe_load((ROOT / "docker-compose.yml").read_text())


def darkread_commands(compose: dict[str, Any]) -> dict[str, list[str]]:
    return {
        name: service["command"][1:]
        for name, service in compose["services"].items()
        if service.get("command", [None])[0] == "darkread"
    }


def test_the_file_follows_the_compose_specification(compose: dict[str, Any]) -> None:
    import json

    schema = json.loads(SCHEMA.read_text())
    validator = jsonschema.validators.validator_for(schema)(schema)
    assert isinstance(compose.get("name"), str)
    errors = sorted(validator.iter_errors({k: v for k, v in compose.items() if k != "name"}), key=lambda e: list(e.path))
    assert not errors, "\n".join(f"{'/'.join(map(str, e.path))}: {e.message}" for e in errors)
    broken = dict(services={"cloud-a": dict(compose["services"]["cloud-a"], restart_policy="always")})
    assert not validator.is_valid(broken)  # the schema does refuse unknown keys


def test_two_cloud_instances_share_one_postgres_and_the_edge_knows_both(compose: dict[str, Any]) -> None:
    services = compose["services"]
    clouds = [name for name, s in services.items() if s.get("command", [])[:3] == ["darkread", "cloud", "serve"]]
    assert clouds == ["cloud-a", "cloud-b"]
    urls = {services[name]["environment"]["DARKREAD_DATABASE_URL"] for name in clouds}
    assert len(urls) == 1 and "@postgres:5432/" in urls.pop()
    assert all(services[name]["depends_on"]["postgres"]["condition"] == "service_healthy" for name in clouds)
    assert {p.split(":")[-1] for name in clouds for p in services[name]["ports"]} == {"8000"}  # the port serve listens on
    edge = services["edge"]["command"]
    targets = [edge[i + 1] for i, word in enumerate(edge) if word == "--cloud"]
    assert targets == [f"ws://{name}:8000/v1/stream" for name in clouds]
    assert set(services["edge"]["depends_on"]) == set(clouds)
    assert services["postgres"]["image"].startswith("postgres:")
    assert "pg_isready" in services["postgres"]["healthcheck"]["test"]
    replay = edge[edge.index("--replay") + 1]
    assert (ROOT / replay.removeprefix("/app/")).is_dir()  # the Dockerfile copies the tree to /app


def test_every_darkread_command_parses(compose: dict[str, Any]) -> None:
    commands = darkread_commands(compose)
    assert set(commands) == {"cloud-a", "cloud-b", "edge"}
    parser = build_parser()
    for name, argv in commands.items():
        args = parser.parse_args(argv)  # unknown sub-commands or flags exit 2 here
        assert callable(args.func), name


@pytest.mark.parametrize("words", [["cloud", "serve"], ["edge", "run"]])
def test_the_commands_compose_runs_explain_themselves(compose: dict[str, Any], words: list[str]) -> None:
    used = {name for name, argv in darkread_commands(compose).items() if argv[:2] == words}
    assert used
    done = subprocess.run([sys.executable, "-m", "darkread", *words, "--help"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    for argv in (argv for name, argv in darkread_commands(compose).items() if name in used):
        for flag in (word for word in argv if word.startswith("--")):
            assert flag in done.stdout, f"{flag} is not in `darkread {' '.join(words)} --help`"
