"""Host and device (lonlib.ddpg.devices): every copy is counted and owns its memory, and the
CPU can take every path a CUDA device takes (the `device_mode` fixture)."""

import numpy as np
import pytest
import torch

from lonlib.ddpg.devices import (
    Transfer,
    TransferLog,
    copy_to_device,
    cpu_as_device,
    host_view,
    is_host,
    to_device,
    to_host,
)
from lonlib.ddpg.trainer import check_device


def test_the_cpu_is_the_host_unless_the_tests_switch_makes_it_a_device():
    assert is_host("cpu") and is_host(torch.device("cpu")) and not is_host("meta")
    with cpu_as_device():
        assert not is_host("cpu")
        with cpu_as_device():
            assert not is_host("cpu")
        assert not is_host("cpu")  # nested: the outer switch still holds
    assert is_host("cpu")


def test_copies_never_share_memory_and_every_one_is_counted():
    host = np.arange(6, dtype=np.float64).reshape(2, 3)
    with TransferLog() as log:
        tensor = to_device(host, "cpu", torch.float32)
        host[0, 0] = 100.0
        assert tensor.dtype == torch.float32 and tensor[0, 0] == 0.0
        back = to_host(tensor)
        back[1, 1] = -1.0
        assert tensor[1, 1] == 4.0
        out = torch.zeros(2, 3, dtype=torch.float64)
        copy_to_device(host[:, ::-1], out)  # a strided array, cast to out's dtype
        assert out[0, 2] == 100.0
        assert to_device(torch.ones(2), "cpu").dtype == torch.float32
    assert [t.direction for t in log.transfers] == ["to device", "to host"] + ["to device"] * 2
    assert log.count("to device") == 3 and log.count("to host") == 1
    assert log.transfers[0] == Transfer("to device", (2, 3), torch.float32)
    view = host_view(tensor)
    view[0, 1] = 7.0  # a view, not a copy
    assert tensor[0, 1] == 7.0
    with pytest.raises(ValueError, match="host memory"):
        host_view(torch.zeros(1, device="meta"))
    with cpu_as_device(), pytest.raises(ValueError, match="host memory"):
        host_view(tensor)  # the CPU is a device now: no view of its memory


def test_a_cuda_device_is_checked_against_the_devices_torch_sees(monkeypatch):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 1)
    check_device("cuda")
    check_device("cuda:0")
    with pytest.raises(ValueError, match="this machine has 1 CUDA device"):
        check_device("cuda:1")
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    with pytest.raises(ValueError, match="torch sees no CUDA device here"):
        check_device("cuda")
