"""Edge configuration: TOML, environment, command-line overrides, the shipped files."""

from __future__ import annotations

from pathlib import Path

import pytest

from darkread.edge.config import EdgeConfig, load_config


def test_config_toml_env_and_overrides(tmp_path: Path) -> None:
    toml = tmp_path / "edge.toml"
    toml.write_text('[uplink]\nurl = "ws://cloud:1/v1/stream"\nmode = "pages"\n[pipeline]\nn_events = 800\n')
    env = {"DARKREAD_EDGE_UPLINK_API_KEY": "secret", "DARKREAD_EDGE_PIPELINE_LOSSLESS": "yes", "HOME": "/x"}
    config = load_config(toml, environ=env, overrides={"source": {"speed": 0.0}})
    assert config.uplink.url == "ws://cloud:1/v1/stream"
    assert config.uplink.mode == "pages"
    assert config.uplink.api_key == "secret"
    assert config.pipeline.n_events == 800 and config.pipeline.lossless is True
    assert config.source.speed == 0.0
    assert config.metrics == EdgeConfig().metrics


def test_config_env_beats_file_and_types_are_checked(tmp_path: Path) -> None:
    toml = tmp_path / "edge.toml"
    toml.write_text("[pipeline]\nn_events = 800\n")
    assert load_config(toml, environ={"DARKREAD_EDGE_PIPELINE_N_EVENTS": "1200"}).pipeline.n_events == 1200
    with pytest.raises(ValueError, match="n_events"):
        load_config(toml, environ={"DARKREAD_EDGE_PIPELINE_N_EVENTS": "many"})


@pytest.mark.parametrize(
    "text",
    ["[uplink]\nmode = 'video'\n", "[nosuch]\nx = 1\n", "[uplink]\nnosuch = 1\n", "not toml [",
     "[pipeline]\nrenew_fraction = 0\n", "[pipeline]\nrenew_fraction = 1.5\n", "[pipeline]\ndither_px = -5\n",
     "[pipeline]\nsettle_max_doubt = 0\n"],
)
def test_config_rejects_bad_files(tmp_path: Path, text: str) -> None:
    toml = tmp_path / "edge.toml"
    toml.write_text(text)
    with pytest.raises(ValueError):
        load_config(toml, environ={})


def test_shipped_example_config_loads() -> None:
    import darkread.edge

    example = Path(darkread.edge.__file__).parent / "systemd" / "edge.toml"
    config = load_config(example, environ={})
    assert config.uplink.spool_dir.startswith("/var/lib/darkread")


def test_unit_file_is_notify_with_watchdog_and_hardening() -> None:
    import darkread.edge

    unit = (Path(darkread.edge.__file__).parent / "systemd" / "darkread-edge.service").read_text()
    directives = {}
    for line in unit.splitlines():
        if "=" in line and not line.startswith("#"):
            key, _, value = line.partition("=")
            directives.setdefault(key.strip(), value.strip())
    assert directives["Type"] == "notify"
    assert directives["WatchdogSec"].endswith("s")
    assert directives["ProtectSystem"] == "strict"
    assert directives["NoNewPrivileges"] == "yes"
    assert directives["StateDirectory"] == "darkread-edge"
    assert "edge run" in directives["ExecStart"]
    # numba caches the compiled loops where the daemon may write (/usr is read-only to it)
    environment = dict(line.removeprefix("Environment=").split("=", 1) for line in unit.splitlines() if line.startswith("Environment="))
    assert environment["NUMBA_CACHE_DIR"].startswith(f"/var/cache/{directives['CacheDirectory']}/")
    rules = Path(darkread.edge.__file__).parent / "systemd" / "99-darkread-evk4.rules"
    if rules.is_file():  # the camera's group is the one the udev rule assigns
        import re

        groups = set(re.findall(r'GROUP="([^"]+)"', rules.read_text()))
        assert groups == {directives["SupplementaryGroups"]}
    else:
        assert directives["SupplementaryGroups"]


def test_several_cloud_urls_from_repeated_options_toml_lists_and_the_environment(tmp_path: Path) -> None:
    import argparse

    from darkread.edge.cli import overrides_from_args, register
    from darkread.edge.uplink import split_urls

    parser = argparse.ArgumentParser()
    register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["edge", "run", "--cloud", "ws://a:1/v1/stream", "--cloud", "ws://b:1/v1/stream,ws://c:1/v1/stream"])
    config = load_config(None, environ={}, overrides=overrides_from_args(args))
    assert split_urls(config.uplink.url) == ("ws://a:1/v1/stream", "ws://b:1/v1/stream", "ws://c:1/v1/stream")
    toml = tmp_path / "edge.toml"
    toml.write_text('[uplink]\nurl = ["ws://a:1/v1/stream", "wss://b/v1/stream"]\n')
    assert split_urls(load_config(toml, environ={}).uplink.url) == ("ws://a:1/v1/stream", "wss://b/v1/stream")
    environ = {"DARKREAD_EDGE_UPLINK_URL": "ws://x:1/v1/stream, ws://y:1/v1/stream"}
    assert split_urls(load_config(None, environ=environ).uplink.url) == ("ws://x:1/v1/stream", "ws://y:1/v1/stream")
    with pytest.raises(ValueError, match="not a ws:// or wss:// URL"):
        load_config(None, environ={"DARKREAD_EDGE_UPLINK_URL": "ws://x:1/v1/stream,http://y"})


def test_edge_run_options_become_config_overrides(tmp_path: Path) -> None:
    import argparse

    from darkread.edge.cli import overrides_from_args, register

    parser = argparse.ArgumentParser()
    register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(
        ["edge", "run", "--replay", "rec", "--cloud", "ws://h:1/v1/stream", "--api-key", "K",
         "--speed", "max", "--mode", "pages", "--spool", str(tmp_path), "--metrics-port", "9100"]
    )
    config = load_config(None, environ={}, overrides=overrides_from_args(args))
    assert config.source.kind == "replay" and config.source.path == "rec" and config.source.speed == 0.0
    assert config.gaze.kind == "recording"
    assert config.uplink.url == "ws://h:1/v1/stream" and config.uplink.api_key == "K"
    assert config.uplink.mode == "pages" and config.uplink.spool_dir == str(tmp_path)
    assert config.metrics.port == 9100
    args = parser.parse_args(["edge", "run", "--speed", "2", "--gaze", "udp", "--gaze-port", "7100"])
    config = load_config(None, environ={}, overrides=overrides_from_args(args))
    assert config.source.speed == 2.0 and config.gaze.kind == "udp" and config.gaze.udp_port == 7100


def test_fuse_must_name_what_a_view_averages(tmp_path) -> None:
    from darkread.edge.config import load_config

    path = tmp_path / "edge.toml"
    path.write_text('[pipeline]\nfuse = "maybe"\n')
    with pytest.raises(ValueError, match="fuse must be 'probability' or 'mask'"):
        load_config(path)
    path.write_text('[pipeline]\nfuse = "mask"\n')
    assert load_config(path).pipeline.fuse == "mask"


def test_sensor_section_sets_the_bias_profile_and_its_switching(tmp_path: Path) -> None:
    toml = tmp_path / "edge.toml"
    toml.write_text('[sensor]\nprofile = "auto"\nlux = 8.0\ndark_below_lux = 12\nbright_above_lux = 30\n')
    config = load_config(toml, environ={"DARKREAD_EDGE_SENSOR_MIN_DWELL_S": "20"})
    assert (config.sensor.lux, config.sensor.dark_below_lux, config.sensor.bright_above_lux) == (8.0, 12.0, 30.0)
    assert config.sensor.min_dwell_s == 20.0 and EdgeConfig().sensor.profile == "auto"


@pytest.mark.parametrize("values, message", [
    ({"profile": "night"}, "profile must be auto, factory or dark"),
    ({"dark_below_lux": 30.0, "bright_above_lux": 20.0}, "0 < dark_below_lux < bright_above_lux"),
    ({"lux": -1.0}, "lux must be >= 0"),
    ({"estimate_s": 0.0}, "estimate_s must be positive"),
])
def test_sensor_section_refuses_impossible_values(values: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        load_config(environ={}, overrides={"sensor": values})
