"""docs/algorithms.md runs as written: its files are written, its commands run, in order."""

from __future__ import annotations

from pathlib import Path

from tests.docs._tutorial import DOCS, run_tutorial, steps

DOC = DOCS / "algorithms.md"


def test_the_doc_has_files_and_commands() -> None:
    kinds = [k for k, _ in steps(DOC)]
    assert kinds.count("file") >= 3
    assert kinds.count("command") >= 5


def test_the_tutorial_runs(tmp_path: Path) -> None:
    run_tutorial(DOC, tmp_path)
    assert (tmp_path / "runs" / "tall" / "manifest.json").is_file()
    assert (tmp_path / "mine" / "lane_keeper.py").is_file()
    assert list((tmp_path / "runs" / "pipeline").rglob("*.xlsx"))


def test_the_doc_lists_every_field_of_the_types_an_algorithm_sees() -> None:
    # issue 35 item 9: VehicleState's and DetectedObject's fields had to be found by introspection
    import dataclasses

    from redrive import types

    text = (Path(__file__).parents[2] / "docs" / "algorithms.md").read_text()
    section = text[text.index("### The fields, one table per type") :]
    section = section[: section.index("## 3. A detector in one file")]
    for cls in (
        types.Frame,
        types.SensorData,
        types.PointCloud,
        types.Image,
        types.VehicleState,
        types.DetectedObject,
        types.Box3D,
        types.PlannedPath,
        types.ControlCommands,
    ):
        assert f"`{cls.__name__}`" in section, cls.__name__
        for field in dataclasses.fields(cls):
            assert f"`{field.name}`" in section, f"{cls.__name__}.{field.name}"
    for member in types.ObjectClass:
        assert member.name in section
    for member in types.SensorType:
        assert member.name in section
