"""Velodyne VLP-16 / VLP-32C / HDL-32E data packets → points, as nebula decodes them.

A data packet is 1206 bytes: 12 firing blocks of 100 bytes (flag ``0xFFEE``, azimuth in
hundredths of a degree, 32 returns of a 16-bit distance and an 8-bit intensity), a 4-byte
timestamp and two factory bytes (return mode, product id) — the layout of the VLP-16 and
VLP-32C user manuals ("Data Packet Structure").  The arithmetic follows nebula
(``tier4/nebula``, ``nebula_velodyne_decoders/src/decoders/{vlp16,vlp32}_decoder.cpp``,
``unpack``), quirks included, so that a scan decodes to nebula's points:

* azimuths are interpolated between blocks: a 16-laser return at firing ``f``, laser ``d`` lies
  ``diff · (2.304 d + 55.296 f) / 110.592`` hundredths of a degree past its block's azimuth, a
  32-laser return ``j`` at ``diff · 2.304 / 55.296 · j``; ``diff`` is the step to the next block
  (to the next *pair* in dual-return mode) and the packet's last block takes 0 (VLP-16: the last
  but one in dual mode, the last the step before) — nebula's rule, not the manual's
  "use the previous step";
* in dual-return mode, blocks come in pairs of one azimuth; after the first pair nebula gives an
  odd block the azimuth of the pair after it (it reads ``blocks[i + 2]`` for the next step);
  the second return is dropped where it equals the first; ``return_type`` says which return a
  point is (nebula's ``ReturnType`` numbers);
* a return of distance 0, or outside ``(min_range_m, max_range_m)`` (nebula's defaults
  0.3 m and 300 m), is no point; the crop ``cloud_min_angle`` … ``cloud_max_angle`` (degrees,
  wrapping when min > max) is tested on the block azimuth and, for the VLP-16, on the corrected
  azimuth of each point;
* azimuths are rounded to 0.01° before the sine and cosine (nebula's tables), in float32;
* x forward, y left (REP-103): ``x = r cos(ω) cos(α)``, ``y = −r cos(ω) sin(α)``,
  ``z = r sin(ω)`` with ω the laser's vertical angle and α the azimuth.

A VLP-16 packet stops at its first block whose flag is not ``0xFFEE`` (nebula: "bad packet: skip
the rest"); a 32-laser packet skips such a block (nebula would read a ``0xDDFF`` block as lasers
32–63, which these models do not have).  An azimuth of 36000 or more is damage: its block is
skipped.

Everything is numpy over (packets, 12 blocks, 32 returns) arrays; no loop per point.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from redrive.io.ros.decoders.velodyne_models import MODELS_BY_PRODUCT_ID, ReturnMode, VelodyneModel

__all__ = [
    "PACKET_SIZE_BYTES",
    "VelodynePoints",
    "VelodyneSettings",
    "decode_packets",
    "packet_model",
]

PACKET_SIZE_BYTES = 1206
_BLOCKS = 12
_RETURNS = 32
_UPPER_BANK = 0xEEFF  # the 0xFF 0xEE flag read as a little-endian uint16
_FULL_TURN = 36000  # hundredths of a degree

# nebula_common.hpp ReturnType
_LAST = 1
_STRONGEST = 3
_FIRST_WEAK = 4
_LAST_WEAK = 5
_IDENTICAL = 6
_FIRST_STRONGEST = 9
_LAST_STRONGEST = 10

_F32 = np.float32


@dataclass(frozen=True, slots=True, kw_only=True)
class VelodyneSettings:
    """What nebula's driver is configured with (its ``VLP16.param.yaml`` defaults).

    Attributes:
        min_range_m, max_range_m: returns at these distances or beyond are no points.
        cloud_min_angle_deg, cloud_max_angle_deg: the azimuth crop, degrees (0 … 360 keeps
            all; min > max wraps through 0).
        dual_timing_table: which firing-time table ``firing_offset_ns`` uses: None, the one of
            the packets' return mode (in dual mode a block pair fires at once, the manuals'
            timing); False, the single-return table whatever the packets say — what nebula uses
            in practice, since its ``return_mode_from_string("Dual")`` gives ``DUAL_ONLY`` and
            its decoders build the dual table only for ``DUAL``.
    """

    min_range_m: float = 0.3
    max_range_m: float = 300.0
    cloud_min_angle_deg: int = 0
    cloud_max_angle_deg: int = 360
    dual_timing_table: bool | None = None


@dataclass(frozen=True, slots=True, kw_only=True)
class VelodynePoints:
    """The points of some packets, in nebula's order (packet, block, firing, laser).

    Attributes:
        model: the sensor model the factory byte names.
        return_mode: the packets' return mode.
        xyz: float32 (N, 3), metres, x forward, y left, z up.
        intensity: uint8 (N,).
        ring: uint16 (N,), the laser's rank by vertical angle (0 = lowest).
        return_type: uint8 (N,), nebula's ReturnType.
        azimuth_rad: float32 (N,), the corrected azimuth (VLP-16) or the block's (32 lasers, as
            nebula gives it), clockwise from the sensor's y axis as the manual measures it.
        distance_m: float32 (N,).
        packet: int64 (N,), the index of the packet each point came from.
        firing_offset_ns: int64 (N,), when the laser fired after the packet's first firing
            (nebula's timing table).
        azimuth_centideg: int64 (N,), the rounded corrected azimuth in 0.01°.
    """

    model: VelodyneModel
    return_mode: int
    xyz: npt.NDArray[np.float32]
    intensity: npt.NDArray[np.uint8]
    ring: npt.NDArray[np.uint16]
    return_type: npt.NDArray[np.uint8]
    azimuth_rad: npt.NDArray[np.float32]
    distance_m: npt.NDArray[np.float32]
    packet: npt.NDArray[np.int64]
    firing_offset_ns: npt.NDArray[np.int64]
    azimuth_centideg: npt.NDArray[np.int64]


def _rotation_tables() -> tuple[npt.NDArray[np.float32], ...]:
    # nebula: rotation = float(from_degrees(0.01 * i)); cosf / sinf of it.
    radians = (np.arange(_FULL_TURN, dtype=np.float64) * 0.01 * math.pi / 180.0).astype(_F32)
    for table in (radians, cos := np.cos(radians), sin := np.sin(radians)):
        table.flags.writeable = False
    return radians, cos, sin


_ROT_RAD, _COS, _SIN = _rotation_tables()


def packet_model(packets: npt.NDArray[np.uint8]) -> tuple[VelodyneModel, int]:
    """The model and return mode the factory bytes of ``packets`` (P, 1206) name.

    Raises:
        ValueError: a product id that is not a VLP-16, VLP-32C or HDL-32E, an unknown return
            mode, or packets that disagree.
    """
    ids = np.unique(packets[:, 1205])
    modes = np.unique(packets[:, 1204])
    if ids.size != 1 or modes.size != 1:
        msg = (
            f"the packets' factory bytes disagree (product ids {ids.tolist()}, return modes "
            f"{modes.tolist()}): one scan comes from one sensor in one mode"
        )
        raise ValueError(msg)
    model = MODELS_BY_PRODUCT_ID.get(int(ids[0]))
    if model is None:
        known = ", ".join(f"0x{k:02x} {m.name}" for k, m in MODELS_BY_PRODUCT_ID.items())
        msg = f"product id 0x{int(ids[0]):02x} (packet byte 1205) is not a model redrive decodes ({known})"
        raise ValueError(msg)
    mode = int(modes[0])
    if mode not in {m.value for m in ReturnMode}:
        msg = (
            f"return mode 0x{mode:02x} (packet byte 1204) is none of 0x37 strongest, 0x38 last, "
            "0x39 dual"
        )
        raise ValueError(msg)
    return model, mode


def _block_azimuths(
    rotation: npt.NDArray[np.int64], *, dual: bool, sixteen: bool
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Each block's azimuth and step to the next, (P, 12), by nebula's loop (see the module)."""
    step = 2 if dual else 1
    own = np.minimum(np.arange(_BLOCKS) + (step - 1), _BLOCKS - 1)
    own[0] = 0
    azimuth = rotation[:, own]
    diff = np.zeros_like(azimuth)
    measured = _BLOCKS - step  # blocks with a next one to measure the step to
    diff[:, :measured] = (
        _FULL_TURN + rotation[:, step : step + measured] - azimuth[:, :measured]
    ) % _FULL_TURN
    last = diff[:, measured - 1 : measured]
    zero_block = (_BLOCKS - step) if sixteen else (_BLOCKS - 4 * dual - 1)
    for b in range(measured, _BLOCKS):
        diff[:, b] = 0 if b == zero_block else last[:, 0]
    return azimuth, diff


def _in_window(
    values: npt.NDArray[np.int64], settings: VelodyneSettings, *, wrap_all: bool
) -> npt.NDArray[np.bool_]:
    lo = settings.cloud_min_angle_deg * 100
    hi = settings.cloud_max_angle_deg * 100
    if lo < hi:
        return (values >= lo) & (values <= hi)
    if lo > hi:
        if wrap_all:
            return np.ones(values.shape, np.bool_)
        return (values <= hi) | (values >= lo)
    return np.zeros(values.shape, np.bool_)


def decode_packets(
    packets: npt.NDArray[np.uint8], *, settings: VelodyneSettings | None = None
) -> VelodynePoints:
    """The points of ``packets`` (uint8 (P, 1206), one sensor's, in order of arrival).

    Raises:
        ValueError: the array is not (P, 1206) uint8, or the factory bytes name no model redrive
            decodes (:func:`packet_model`).
    """
    settings = settings or VelodyneSettings()
    if packets.dtype != np.uint8 or packets.ndim != 2 or packets.shape[1] != PACKET_SIZE_BYTES:
        msg = (
            f"Velodyne data packets are {PACKET_SIZE_BYTES} bytes, got an array of shape "
            f"{packets.shape} ({packets.dtype})"
        )
        raise ValueError(msg)
    model, mode = packet_model(packets)
    dual = mode == ReturnMode.DUAL
    sixteen = model.firings_per_block == 2
    n_packets = packets.shape[0]
    blocks = packets[:, : _BLOCKS * 100].reshape(n_packets, _BLOCKS, 100)
    flag = blocks[:, :, 0].astype(np.int64) | (blocks[:, :, 1].astype(np.int64) << 8)
    rotation = blocks[:, :, 2].astype(np.int64) | (blocks[:, :, 3].astype(np.int64) << 8)
    good = (flag == _UPPER_BANK) & (rotation < _FULL_TURN)
    if sixteen:
        good = np.cumprod(good, axis=1, dtype=np.bool_)  # the rest of the packet is skipped
    returns = blocks[:, :, 4:].reshape(n_packets, _BLOCKS, _RETURNS, 3)
    raw = returns[..., 0].astype(np.int64) | (returns[..., 1].astype(np.int64) << 8)
    intensity = returns[..., 2]
    partner = np.arange(_BLOCKS) ^ 1  # the other block of a dual-return pair
    raw_other = raw[:, partner, :]
    odd = (np.arange(_BLOCKS) % 2 == 1)[None, :, None]

    azimuth, diff = _block_azimuths(np.where(good, rotation, 0), dual=dual, sixteen=sixteen)
    j = np.arange(_RETURNS)
    laser = j % 16 if sixteen else j
    rot_centideg = model.rot_rad.astype(_F32).astype(np.float64) * 180.0 / math.pi * 100
    if sixteen:
        firing = (j // 16).astype(_F32)
        within = (j % 16).astype(_F32) * _F32(2.304) + firing * _F32(55.296)
        shift = diff.astype(_F32)[:, :, None] * within[None, None, :] / _F32(110.592)
    else:
        shift = diff.astype(_F32)[:, :, None] * _F32(2.304) / _F32(55.296) * j.astype(_F32)
    corrected = (azimuth.astype(_F32)[:, :, None] + shift).astype(np.float64)
    corrected = (corrected - rot_centideg[laser][None, None, :]).astype(_F32)
    corrected = np.where(
        corrected < 0, (corrected.astype(np.float64) + _FULL_TURN).astype(_F32), corrected
    )
    az_centideg = (
        np.floor(corrected.astype(np.float64) + 0.5).astype(np.int64) % 65536
    ) % _FULL_TURN

    distance = raw.astype(_F32) * _F32(model.distance_resolution_m)
    keep = good[:, :, None] & (raw != 0)
    if dual:
        keep &= ~(odd & (raw_other == raw))
    keep &= (distance > settings.min_range_m) & (distance < settings.max_range_m)
    if sixteen:
        keep &= _in_window(azimuth, settings, wrap_all=True)[:, :, None]
        keep &= _in_window(az_centideg, settings, wrap_all=False)
    else:
        keep &= _in_window(rotation, settings, wrap_all=False)[:, :, None]

    p_idx, b_idx, j_idx = np.nonzero(keep)
    az = az_centideg[p_idx, b_idx, j_idx]
    dist = distance[p_idx, b_idx, j_idx]
    las = laser[j_idx]
    vert = model.vert_rad.astype(_F32)
    cos_v, sin_v = np.cos(vert)[las], np.sin(vert)[las]
    xy = dist * cos_v
    xyz = np.empty((dist.shape[0], 3), _F32)
    xyz[:, 0] = xy * _COS[az]
    xyz[:, 1] = -(xy * _SIN[az])
    xyz[:, 2] = dist * sin_v
    inten = intensity[p_idx, b_idx, j_idx]
    return_type = _return_types(
        mode,
        sixteen=sixteen,
        raw=raw[p_idx, b_idx, j_idx],
        raw_other=raw_other[p_idx, b_idx, j_idx],
        intensity=inten,
        intensity_other=intensity[:, partner, :][p_idx, b_idx, j_idx],
    )
    dual_table = dual if settings.dual_timing_table is None else settings.dual_timing_table
    if sixteen:
        block_index = (b_idx - b_idx % 2 if dual_table else b_idx * 2) + j_idx // 16
        point_index = j_idx % 16
    else:
        block_index = b_idx // 2 if dual_table else b_idx
        point_index = j_idx // 2
    firing_ns = np.rint((55.296e-6 * block_index + 2.304e-6 * point_index) * 1e9).astype(np.int64)
    azimuth_rad = _ROT_RAD[az] if sixteen else _ROT_RAD[rotation[p_idx, b_idx]]
    return VelodynePoints(
        model=model,
        return_mode=mode,
        xyz=xyz,
        intensity=inten,
        ring=model.rings[las],
        return_type=return_type,
        azimuth_rad=azimuth_rad,
        distance_m=dist,
        packet=p_idx.astype(np.int64),
        firing_offset_ns=firing_ns,
        azimuth_centideg=az,
    )


def _return_types(
    mode: int,
    *,
    sixteen: bool,
    raw: npt.NDArray[np.int64],
    raw_other: npt.NDArray[np.int64],
    intensity: npt.NDArray[np.uint8],
    intensity_other: npt.NDArray[np.uint8],
) -> npt.NDArray[np.uint8]:
    """nebula's ``return_type`` of each point (its ``switch (return_mode)``)."""
    if mode == ReturnMode.STRONGEST:
        return np.full(raw.shape, _STRONGEST, np.uint8)
    if mode == ReturnMode.LAST:
        return np.full(raw.shape, _LAST, np.uint8)
    # Dual: which of the pair is first and which strongest.  The two decoders differ: the
    # VLP-16 one calls the farther return "first", the VLP-32 one the nearer (or equal).
    first = raw > raw_other if sixteen else raw <= raw_other
    strongest = np.where(intensity == intensity_other, ~first, intensity > intensity_other)
    out = np.where(
        first,
        np.where(strongest, _FIRST_STRONGEST, _FIRST_WEAK),
        np.where(strongest, _LAST_STRONGEST, _LAST_WEAK),
    ).astype(np.uint8)
    out[(raw_other == 0) | (raw_other == raw)] = _IDENTICAL
    return out
