"""Configuration (L1): the pipeline a run executes and the one validator of user configuration.

:mod:`redrive.config.pipeline` holds the pipeline model and its TOML loader;
:mod:`redrive.config.validate` the typed reader every config file of redrive goes through
(pipelines, scenarios, sensor rigs, sensor maps, batch specs, run manifests).  Both import only
:mod:`redrive.errors`, so every layer above L0 can use them.
"""

from __future__ import annotations

from redrive.config.pipeline import (
    AlgorithmSpec,
    Executor,
    PipelineConfig,
    RunMode,
    StageSpec,
    load_pipeline,
    object_level_pipeline,
    pipeline_from_plugins,
    reference_pipeline,
)

__all__ = [
    "AlgorithmSpec",
    "Executor",
    "PipelineConfig",
    "RunMode",
    "StageSpec",
    "load_pipeline",
    "object_level_pipeline",
    "pipeline_from_plugins",
    "reference_pipeline",
]
