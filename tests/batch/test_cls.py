"""nuPlan's CLS over a batch: ``nuplan_scenario_score`` pooled as the plain mean of the
scenarios' scores (each log counting once), stored and printed as ``cls``."""

from __future__ import annotations

from pathlib import Path

import pytest

from redrive.batch.evaluate import evaluate_batch, read_cell_values, read_pooled
from redrive.cli.main import main
from redrive.evaluation.closedloop import NuplanScenarioScore

FOLLOWER = Path(__file__).parents[1] / "closedloop" / "data" / "follower.toml"


def test_cls_is_the_mean_of_the_scenario_scores(tmp_path: Path) -> None:
    out = tmp_path / "batch"
    code = main(
        [
            "batch", str(FOLLOWER), "--seeds", "1-3", "--loop", "closed", "--duration", "3",
            "--planning", "tests.closedloop.plugins:Jerky", "--workers", "1", "-o", str(out),
            "--no-progress",
        ]
    )  # fmt: skip
    assert code == 0
    evaluate_batch(out, metrics=[NuplanScenarioScore()])
    cells = [
        r
        for r in read_cell_values(out).to_pylist()
        if r["metric"] == "nuplan_scenario_score" and r["key"] == "nuplan_scenario_score"
    ]
    assert len(cells) == 3
    scores = [float(r["value"]) for r in cells]
    pooled = {
        r["key"]: r for r in read_pooled(out).to_pylist() if r["metric"] == "nuplan_scenario_score"
    }
    assert pooled["cls"]["rule"] == "scenario_mean"
    assert pooled["cls"]["logs"] == 3
    assert pooled["cls"]["value"] == pytest.approx(sum(scores) / 3)
