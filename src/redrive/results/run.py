"""Reading a run directory: :func:`open_run` and :class:`Run` (layout: see
:mod:`redrive.results`)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from redrive.errors import ConfigError
from redrive.results._parts import parts_on_disk, read_part
from redrive.results.manifest import RunManifest, read_manifest
from redrive.results.readers import (
    commands_by_frame,
    ego_by_frame,
    objects_by_frame,
    paths_by_frame,
)
from redrive.results.roadmap import read_road_map
from redrive.results.schema import SCHEMAS, SORT_KEYS, TABLES
from redrive.results.summary import summarize_steps
from redrive.types import (
    ControlCommands,
    DetectedObject,
    LightState,
    PlannedPath,
    RoadMap,
    TrafficLight,
    VehicleState,
)

__all__ = ["Run", "check_table", "open_run"]


def open_run(run_dir: str | Path) -> Run:
    """Open a run directory for reading.

    Raises:
        ConfigError: ``run_dir`` does not exist, is not a run, or its manifest is unreadable.
    """
    path = Path(run_dir)
    if not path.is_dir():
        msg = f"{path}: no such run directory (give the --out of a `redrive run`)"
        raise ConfigError(msg)
    return Run(path, read_manifest(path))


class Run:
    """A run directory, read side.  Reads the parts on disk at each call (a live run grows).

    Attributes:
        path: the run directory.
        manifest: ``manifest.json`` as read (and validated) by :func:`open_run`.
    """

    def __init__(self, path: Path, manifest: RunManifest) -> None:
        self.path = path
        self.manifest = manifest

    def __repr__(self) -> str:
        return f"Run({str(self.path)!r}, status={self.manifest.status.value!r})"

    def part_paths(self, name: str) -> list[Path]:
        """The committed parts of table ``name``, in write order."""
        check_table(name)
        committed = parts_on_disk(self.path, "frames")
        if name == "frames":
            return list(committed.values())
        return [p for n, p in parts_on_disk(self.path, name).items() if n in committed]

    def tables(self) -> tuple[str, ...]:
        """The tables with at least one row, in :data:`~redrive.results.schema.TABLES` order."""
        out = []
        for name in TABLES:
            for part in self.part_paths(name):
                try:
                    rows = pq.ParquetFile(part).metadata.num_rows
                except (OSError, pa.ArrowException) as err:
                    msg = f"{part}: cannot read this part of the run ({err})"
                    raise ConfigError(msg) from err
                if rows:
                    out.append(name)
                    break
        return tuple(out)

    def _raw(self, name: str) -> pa.Table:
        schema = SCHEMAS[name]
        parts = [read_part(p, schema) for p in self.part_paths(name)]
        return pa.concat_tables(parts) if parts else schema.empty_table()

    def raw_columns(self, name: str, columns: Sequence[str]) -> pa.Table:
        """``columns`` of all parts of ``name`` in write order (unsorted, as read)."""
        check_table(name)
        schema = SCHEMAS[name]
        parts = [read_part(p, schema, columns) for p in self.part_paths(name)]
        if parts:
            return pa.concat_tables(parts)
        return pa.schema([schema.field(c) for c in columns]).empty_table()

    def table(self, name: str) -> pa.Table:
        """All parts of ``name`` concatenated, stably sorted by ``SORT_KEYS[name]``."""
        check_table(name)
        table = self._raw(name)
        return table.sort_by([(key, "ascending") for key in SORT_KEYS[name]])

    def summary(self) -> pa.Table:
        """Per algorithm, in pipeline order: frames, statuses, outputs, latency and CPU (ms).

        See :func:`redrive.results.summary.summarize_steps` for the columns.
        """
        return summarize_steps(self._raw("steps"))

    def _ok_frames(self, algorithm: str) -> list[int]:
        steps = self._raw("steps")
        mine = steps.filter(pc.equal(steps.column("algorithm"), algorithm))
        if mine.num_rows == 0:
            have = sorted(set(steps.column("algorithm").to_pylist()))
            msg = f"{self.path}: no algorithm {algorithm!r} in this run (it has {have})"
            raise ValueError(msg)
        ok = mine.filter(pc.equal(mine.column("status"), "ok"))
        return sorted(ok.column("frame_index").to_pylist())

    def _of(self, name: str, algorithm: str) -> pa.Table:
        table = self.table(name)
        return table.filter(pc.equal(table.column("algorithm"), algorithm))

    def detections(self, algorithm: str) -> dict[int, tuple[DetectedObject, ...]]:
        """frame_index → objects ``algorithm`` returned, for every frame its step was ``ok``
        (an empty tuple when it found nothing); frames where it failed are absent."""
        frames = self._ok_frames(algorithm)
        return objects_by_frame(self._of("detections", algorithm), frames=frames)

    def ground_truth(self) -> dict[int, tuple[DetectedObject, ...]]:
        """frame_index → ground-truth objects, for every frame that had ground truth."""
        frames = self.table("frames")
        has = frames.filter(pc.is_valid(frames.column("n_ground_truth")))
        return objects_by_frame(
            self.table("ground_truth"), frames=has.column("frame_index").to_pylist()
        )

    def paths(self, algorithm: str) -> dict[int, PlannedPath]:
        """frame_index → the path ``algorithm`` planned (frames with a non-empty path)."""
        self._ok_frames(algorithm)
        return paths_by_frame(self._of("paths", algorithm))

    def commands(self, algorithm: str) -> dict[int, ControlCommands]:
        """frame_index → the commands ``algorithm`` gave."""
        self._ok_frames(algorithm)
        return commands_by_frame(self._of("commands", algorithm))

    def ego(self) -> dict[int, VehicleState]:
        """frame_index → the ego state of the frame (frame ``map``/``odom`` as recorded)."""
        return ego_by_frame(self.table("ego"))

    def logged_ego(self) -> dict[int, VehicleState]:
        """frame_index → the ego state the log recorded, where the run stored it apart from the
        driven ego (closed loop); empty otherwise (open loop: :meth:`ego` *is* the logged ego)."""
        return ego_by_frame(self.table("ego_logged"))

    def traffic_lights(self) -> dict[int, tuple[TrafficLight, ...]]:
        """frame_index → the traffic lights' states of the frame, for every frame that had any
        (``Frame.traffic``); empty when the run's log has no light states.

        Raises:
            ConfigError: a stored state is not a :class:`~redrive.types.LightState` value.
        """
        table = self.table("traffic_lights")
        out: dict[int, list[TrafficLight]] = {}
        states = {s.value: s for s in LightState}
        for fi, light_id, state in zip(
            table.column("frame_index").to_pylist(),
            table.column("light_id").to_pylist(),
            table.column("state").to_pylist(),
            strict=True,
        ):
            if state not in states:
                msg = (
                    f"{self.path}: traffic_lights row of frame {fi}, light {light_id!r}: state "
                    f"{state!r} is not one of {', '.join(states)}; the run is damaged"
                )
                raise ConfigError(msg)
            out.setdefault(fi, []).append(TrafficLight(id=light_id, state=states[state]))
        return {fi: tuple(lights) for fi, lights in out.items()}

    def road_map(self) -> RoadMap | None:
        """The run's road map (``RUN/map.json``), None when the run has none.

        Raises:
            ConfigError: the file exists but is not a valid map (the message says where).
        """
        return read_road_map(self.path)


def check_table(name: str) -> None:
    if name not in SCHEMAS:
        msg = f"no table {name!r} in a run; tables are {', '.join(TABLES)}"
        raise ValueError(msg)
