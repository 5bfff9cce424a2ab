"""A device other than the CPU, for a machine without one: CPU tensors tagged with the device they are "on".

Kimodo on CUDA fails where a CPU tensor is indexed with CUDA indices ("indices should be either on
cpu or on the same device as the indexed tensor"). Real tensors cannot live on a GPU here, so the fake
tags the tensors that Kimodo would create on the model's device, and :func:`index` refuses the same
mixes CUDA refuses. ``FAKE_GPU`` is the device name tests give the adapter.
"""

import torch

FAKE_GPU = "fakecuda:0"


def device_of(t) -> str:
    """The device a tensor is (said to be) on."""
    return getattr(t, "fake_device", str(t.device))


def on(t: torch.Tensor, device) -> torch.Tensor:
    """``t`` "moved" to ``device`` (tagged when it is the fake GPU)."""
    if str(device) == FAKE_GPU:
        t = t.clone()
        t.fake_device = FAKE_GPU
        return t
    return t.to(device) if device is not None else t


def tensor(values, device=None, dtype=None) -> torch.Tensor:
    """``torch.tensor(values, device=device)``, the fake GPU allowed."""
    t = torch.tensor(values, dtype=dtype)
    return on(t, device) if device is not None else t


def index(data: torch.Tensor, indices: torch.Tensor) -> torch.Tensor:
    """``data[indices]`` with CUDA's rule: indices on the CPU or on the data's device."""
    where, by = device_of(data), device_of(indices)
    if by != "cpu" and by != where:
        raise RuntimeError(f"indices should be either on cpu or on the same device as the indexed tensor ({where})")
    return data[indices]
