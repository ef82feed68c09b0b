"""Pipeline files: what they say, and clear errors for what they must not say."""

from __future__ import annotations

from pathlib import Path

import pytest

from redrive.config import load_pipeline, pipeline_from_plugins, reference_pipeline
from redrive.errors import ConfigError


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "pipeline.toml"
    path.write_text(text, encoding="utf-8")
    return path


def test_a_full_pipeline_file(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        """
mode = "pipelined"
executor = "processes"
seed = 3
step_timeout_s = 2
fail_fast = true

[[stage]]
name = "detection"
[[stage.algorithm]]
name = "a"
plugin = "algos/det.py:Det"
config = { voxel_m = 0.2, rules = { car = [1, 2] } }
[[stage.algorithm]]
plugin = "noisy-oracle"

[[stage]]
[[stage.algorithm]]
plugin = "pkg.mod:Planner"
""",
    )
    p = load_pipeline(path)
    assert (p.mode, p.executor, p.seed, p.step_timeout_s, p.fail_fast) == (
        "pipelined",
        "processes",
        3,
        2.0,
        True,
    )
    assert [s.name for s in p.stages] == ["detection", "stage_2"]
    first, oracle = p.stages[0].algorithms
    assert first.plugin == f"{(tmp_path / 'algos/det.py').as_posix()}:Det"  # relative to the file
    assert first.config["rules"] == {"car": [1, 2]}
    assert oracle.name == "noisy-oracle"
    assert p.stages[1].algorithms[0].name == "Planner"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ('mode = "fast"\n[[stage]]\n[[stage.algorithm]]\nplugin = "x:Y"', "mode must be"),
        ("colour = 1\n", "unknown key"),
        ("", "at least one stage"),
        ("[[stage]]\nname = 's'\n", "has no algorithm"),
        ('[[stage]]\n[[stage.algorithm]]\nplugin = "a:A"\nwhat = 1', "unknown key"),
        ('[[stage]]\n[[stage.algorithm]]\nname = "x"', "`plugin` must be a string"),
        (
            '[[stage]]\n[[stage.algorithm]]\nname="d"\nplugin="a:A"\n'
            '[[stage.algorithm]]\nname="d"\nplugin="b:B"',
            "two algorithms are named 'd'",
        ),
        ('step_timeout_s = -1\n[[stage]]\n[[stage.algorithm]]\nplugin = "a:A"', "> 0"),
        ("mode = [", "not valid TOML"),
    ],
)
def test_bad_files_say_what_is_wrong(tmp_path: Path, text: str, message: str) -> None:
    with pytest.raises(ConfigError, match=message) as err:
        load_pipeline(write(tmp_path, text))
    assert "pipeline.toml" in str(err.value)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="not found"):
        load_pipeline(tmp_path / "nope.toml")


def test_pipeline_from_flags_orders_roles() -> None:
    p = pipeline_from_plugins(
        perception=["det.py:Det", "kalman-tracker"], control=["pure-pursuit-pid"]
    )
    assert [s.name for s in p.stages] == ["perception_1", "perception_2", "control"]
    assert [a.name for a in p.algorithms] == ["Det", "kalman-tracker", "pure-pursuit-pid"]
    with pytest.raises(ConfigError):
        pipeline_from_plugins()


def test_the_reference_pipeline_names_installed_plugins() -> None:
    from redrive.algorithms import installed_algorithms

    installed = installed_algorithms()
    for algo in reference_pipeline().algorithms:
        assert algo.plugin in installed
