"""GPU placement of a worker: which EGL device renders its scenes and which CUDA device runs its policy.

Worker slot ``k`` (worker id ``w<k>g<n>``) takes the ``k % n``-th of the ``n`` GPUs it may use, so
W workers spread round-robin over the box's GPUs instead of all rendering and inferring on GPU 0:

* EGL: ``MUJOCO_EGL_DEVICE_ID`` (MuJoCo reads it when a worker creates its first renderer). EGL
  enumerates every NVIDIA device whatever ``CUDA_VISIBLE_DEVICES`` says, in PCI bus order, so the
  id is the GPU's physical index; ``executor.egl_devices`` lists the ids to use (null: every GPU
  the worker may see, unless the environment already sets ``MUJOCO_EGL_DEVICE_ID``; ``[]``: never set).
* CUDA: a policy whose ``policy.device`` is ``cuda`` (or ``auto`` on a box with several GPUs)
  gets ``cuda:<i>``, ``i`` indexing the GPUs CUDA sees; ``executor.cuda_devices`` lists the
  indices to use (null: all; ``[]``: leave ``policy.device`` as given).

GPUs are found without CUDA (nothing is initialised): ``/proc/driver/nvidia/gpus/<pci bus id>``
in bus order, filtered by ``CUDA_VISIBLE_DEVICES`` (indices or ``GPU-…`` UUIDs), whose indices are
taken in bus order (``CUDA_DEVICE_ORDER=PCI_BUS_ID``; CUDA's default fastest-first order agrees on a
box of identical GPUs). Everything here is a pure function of its arguments but :func:`nvidia_gpus`.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

NVIDIA_PROC = Path("/proc/driver/nvidia/gpus")


@dataclass(frozen=True)
class Gpu:
    """A physical NVIDIA GPU: its index in PCI bus order (= its EGL device id) and its UUID."""

    index: int
    uuid: str = ""


@dataclass(frozen=True)
class Placement:
    """Where one worker renders and runs its policy (``None``: not chosen here)."""

    egl_device: int | None = None
    policy_device: str | None = None

    def describe(self) -> str:
        return f"EGL device {self.egl_device}, policy on {self.policy_device}"


def nvidia_gpus(root: Path = NVIDIA_PROC) -> list[Gpu]:
    """The box's NVIDIA GPUs in PCI bus order, read from the driver's ``/proc`` files (none: ``[]``)."""
    try:
        buses = sorted(p for p in root.iterdir() if p.is_dir())
    except OSError:
        return []
    out = []
    for index, bus in enumerate(buses):
        try:
            info = (bus / "information").read_text()
        except OSError:
            info = ""
        match = re.search(r"GPU UUID:\s*(\S+)", info)
        out.append(Gpu(index, match.group(1) if match else ""))
    return out


def visible_gpus(gpus: Sequence[Gpu], env: Mapping[str, str]) -> list[Gpu]:
    """The GPUs CUDA shows this process, in CUDA's index order (``CUDA_VISIBLE_DEVICES`` applied:
    a list of indices or UUID prefixes; it stops at the first entry it cannot match, as CUDA does)."""
    spec = env.get("CUDA_VISIBLE_DEVICES")
    if spec is None:
        return list(gpus)
    out: list[Gpu] = []
    for entry in (e.strip() for e in spec.split(",")):
        if re.fullmatch(r"\d+", entry):
            match = [g for g in gpus if g.index == int(entry)]
        else:
            match = [g for g in gpus if entry and g.uuid.startswith(entry)] if entry.startswith("GPU-") else []
        if len(match) != 1 or match[0] in out:
            break
        out.append(match[0])
    return out


def slot_of(worker_id: str) -> int:
    """The slot index of a supervisor worker id (``w3g1`` → 3); 0 for any other id."""
    match = re.fullmatch(r"w(\d+)g\d+", worker_id)
    return int(match.group(1)) if match else 0


def _devices(value: Any, key: str) -> list[int] | None:
    if value is None:
        return None
    if not isinstance(value, (list, tuple)) or not all(isinstance(v, int) and not isinstance(v, bool) and v >= 0
                                                       for v in value):
        raise ValueError(f"executor.{key}: expected a list of device indices or null, got {value!r}")
    return list(value)


def check_devices(executor: Mapping[str, Any]) -> None:
    """Raise ``ValueError`` naming the key if ``executor.egl_devices`` or ``cuda_devices`` is not a device list."""
    _devices(executor.get("egl_devices"), "egl_devices")
    _devices(executor.get("cuda_devices"), "cuda_devices")


def place(slot: int, gpus: Sequence[Gpu], env: Mapping[str, str], executor: Mapping[str, Any],
          policy_device: str | None) -> Placement:
    """Worker ``slot``'s placement on a box with ``gpus`` (:func:`nvidia_gpus`), given its
    environment, the run's ``executor`` block and the policy's ``policy.device`` (None: it has none)."""
    visible = visible_gpus(gpus, env)
    egl_list = _devices(executor.get("egl_devices"), "egl_devices")
    if egl_list is None:
        egl_list = [] if "MUJOCO_EGL_DEVICE_ID" in env else [g.index for g in visible]
    egl = egl_list[slot % len(egl_list)] if egl_list else None
    cuda_list = _devices(executor.get("cuda_devices"), "cuda_devices")
    if cuda_list is None:
        cuda_list = list(range(len(visible)))
    chosen = executor.get("cuda_devices") is not None
    wants_cuda = policy_device == "cuda" or (policy_device == "auto" and (len(cuda_list) > 1 or chosen))
    device = f"cuda:{cuda_list[slot % len(cuda_list)]}" if wants_cuda and cuda_list else None
    return Placement(egl, device)
