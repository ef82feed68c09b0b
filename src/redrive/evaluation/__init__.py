"""The Evaluation Layer (L3): metrics over run directories, reports, A/B comparison, failure-frame
bookmarks.

>>> from redrive.evaluation import Metric, MetricResult, EvalData
"""

from __future__ import annotations

from redrive.evaluation.base import (
    NEEDS,
    WHOLE_RUN,
    Bookmark,
    EvalData,
    Metric,
    MetricResult,
    MetricSkipped,
    Series,
    params_hash,
)

__all__ = [
    "NEEDS",
    "WHOLE_RUN",
    "Bookmark",
    "EvalData",
    "Metric",
    "MetricResult",
    "MetricSkipped",
    "Series",
    "params_hash",
]
