"""ouster-sdk's decoding of Ouster lidar packets: the reference the Ouster tests compare with.

Run by an interpreter that has ``ouster-sdk`` (it pins ``rosbags==0.9.23``, which redrive's
``rosbags>=0.11`` excludes, so it lives in its own environment, never redrive's)::

    python tests/io/ouster_sdk_reference.py JOB.npz OUT.npz [--sample N]

``JOB.npz`` holds, for each dataset ``name``, ``name/metadata`` (the metadata JSON) and
``name/packets`` (uint8 (P, size), the lidar packets in order).  ``OUT.npz`` gets, per dataset,
ouster-sdk's first complete frame: ``name/range`` (the (H·W,) range image, mm, as
``FrameBatcher`` fills it), ``name/xyz`` (``XYZLut(info)`` of it, metres, float64) and
``name/frame_id``.  ``--sample N`` keeps the xyz of N pixels with a return only (``name/index``)
— what ``tests/io/data/ouster_sdk_reference.npz`` stores, made with ouster-sdk 1.0.1 on
Python 3.11.  Imports nothing of redrive.
"""

from __future__ import annotations

import argparse
import hashlib
import warnings

import numpy as np


def main() -> None:
    from ouster.sdk import core

    parser = argparse.ArgumentParser()
    parser.add_argument("job")
    parser.add_argument("out")
    parser.add_argument("--sample", type=int, default=0)
    args = parser.parse_args()
    warnings.simplefilter("ignore", FutureWarning)  # ScanBatcher / LidarScan are deprecated
    job = np.load(args.job)
    names = sorted({key.split("/")[0] for key in job.files})
    out: dict[str, np.ndarray] = {"ouster_sdk_version": np.array(_version())}
    for name in names:
        info = core.SensorInfo(str(job[f"{name}/metadata"]))
        batcher = core.ScanBatcher(info)
        scan = core.LidarScan(info)
        for raw in job[f"{name}/packets"]:
            packet = core.LidarPacket(len(raw))
            packet.buf[:] = raw
            if batcher(packet, scan):
                break
        rng = scan.field(core.ChanField.RANGE).astype(np.uint32)
        xyz = core.XYZLut(info)(rng).reshape(-1, 3)
        rng = rng.reshape(-1)
        out[f"{name}/frame_id"] = np.array(scan.frame_id)
        out[f"{name}/range_sha256"] = np.array(hashlib.sha256(rng.tobytes()).hexdigest())
        out[f"{name}/returns"] = np.array(int((rng > 0).sum()))
        if args.sample:
            hits = np.flatnonzero(rng)
            index = hits[np.linspace(0, hits.size - 1, args.sample).astype(np.int64)]
            out[f"{name}/index"] = index
            out[f"{name}/xyz"] = xyz[index]
        else:
            out[f"{name}/range"] = rng
            out[f"{name}/xyz"] = xyz
    np.savez_compressed(args.out, **out)


def _version() -> str:
    from importlib.metadata import version

    return version("ouster-sdk")


if __name__ == "__main__":
    main()
