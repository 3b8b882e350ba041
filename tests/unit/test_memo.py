"""The memo of deterministic symbolic results (nonholonomic/memo.py) and its files on disk
(workers/disk_memo.py): what a process derived, the next reads back, identical; a corrupt, truncated,
stale or foreign file is detected, deleted and the value derived again, never trusted."""

from __future__ import annotations

import json
import os
import pickle
import subprocess
import sys
from pathlib import Path

import pytest

from nonholonomic import memo
from workers.disk_memo import MAGIC, DiskMemo

ROOT = Path(__file__).resolve().parents[2]

#: One process's work on Chaplygin's ball (U = 0): definition, heyoka form, kernels, the measure proof,
#: a trajectory; prints what it read back and derived, the proof's detail and the final state.
PROBE = r"""
import json, sys
import numpy as np
from workers.disk_memo import install_disk_memo
disk = install_disk_memo(sys.argv[1])
from nonholonomic.evidence.measure import symbolic_divergence_vanishes
from nonholonomic.numerics.integration import integrate
from nonholonomic.numerics.kernels import numeric, parameter_vector
from nonholonomic.systems import get_system
system = get_system("chaplygin_ball", "zero")
p = parameter_vector(system, {"inertia": [1.0, 1.5, 2.0], "D": 1.0})
y0 = np.array([0.5, 0.3, -0.2, 0.0, 0.6, 0.8])
traj = integrate(system, p, y0, 30.0, 7)
kernels = numeric(system)
energy = kernels.integrals(traj.states, p)[:, 0].tolist()
divergence = kernels.divergence_terms(traj.states, p).sum(axis=1).tolist()
proven, detail = symbolic_divergence_vanishes(system)
print(json.dumps({"hits": disk.hits, "saves": disk.saves, "proven": proven, "detail": detail,
                  "final": traj.states[-1].tolist(), "energy": energy, "divergence": divergence}))
"""


def probe(cache: Path) -> dict:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = subprocess.run([sys.executable, "-c", PROBE, str(cache)], capture_output=True, text=True, env=env,
                         cwd=ROOT, timeout=600)  # hang guard: the probe takes ~10 s when it derives everything
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_a_second_process_reads_back_what_the_first_derived_and_computes_the_same_numbers(tmp_path):
    first = probe(tmp_path)
    assert first["saves"] >= 5 and first["proven"] is True  # definition, heyoka form, kernels, the proof
    second = probe(tmp_path)
    assert second["saves"] == 0 and second["hits"] >= first["saves"]
    # remembered (the hits), and the same words: a verdict's detail holds no time and no origin
    assert second["proven"] is True and second["detail"] == first["detail"]
    # bit for bit: the same integrator, kernels and numbers
    assert second["final"] == first["final"] and second["energy"] == first["energy"]
    assert second["divergence"] == first["divergence"]
    energy = first["energy"]
    assert max(abs(e - energy[0]) for e in energy) <= 1e-12 * abs(energy[0])  # H conserved (eq. 2604-2)
    assert max(abs(d) for d in first["divergence"]) < 1e-12  # div(rho f) = 0 with the remembered kernels


def test_corrupt_truncated_and_stale_files_are_derived_again_with_the_same_numbers(tmp_path):
    first = probe(tmp_path)
    files = sorted(tmp_path.glob("*.memo"))
    assert len(files) == first["saves"]
    for i, path in enumerate(files):
        raw = path.read_bytes()
        if i % 3 == 0:  # a flipped byte in the payload
            path.write_bytes(raw[:-5] + bytes([raw[-5] ^ 0xFF]) + raw[-4:])
        elif i % 3 == 1:  # truncated
            path.write_bytes(raw[: len(raw) // 2])
        else:  # written by another version of the code under the same name
            head, payload = raw[len(MAGIC):].split(b"\n", 1)
            header = json.loads(head)
            header["code"] = "0" * 64
            path.write_bytes(MAGIC + json.dumps(header).encode() + b"\n" + payload)
    second = probe(tmp_path)
    assert second["hits"] == 0 and second["saves"] == first["saves"]  # every value derived again
    assert second["final"] == first["final"] and second["divergence"] == first["divergence"]
    assert second["detail"] == first["detail"]


def test_a_file_is_only_read_under_its_own_key_and_code(tmp_path):
    disk = DiskMemo(tmp_path, code="a" * 64)
    disk.save("kernel:1", b"one")
    assert disk.load("kernel:1") == b"one" and disk.hits == 1
    other = DiskMemo(tmp_path, code="b" * 64)  # another version: another file name, nothing found
    assert other.load("kernel:1") is None
    path = disk.path("kernel:1")
    path.rename(disk.path("kernel:2"))  # the right code, the wrong key in the header
    assert disk.load("kernel:2") is None and not disk.path("kernel:2").exists()
    path.write_bytes(b"not a memo file")
    assert disk.load("kernel:1") is None and not path.exists()


def test_a_value_that_does_not_unpickle_is_discarded_and_computed_again(tmp_path):
    disk = DiskMemo(tmp_path, code="c" * 64)
    previous = memo.installed()
    memo.install(disk)
    try:
        key = memo.key_of("test", ("x", 1))
        disk.save(key, b"\x80\x05garbage")  # a valid file whose payload is no pickle
        calls = []
        assert memo.remember("test", ("x", 1), lambda: calls.append(1) or 42) == 42 and calls == [1]
        assert memo.remember("test", ("x", 1), lambda: calls.append(1) or 42) == 42 and calls == [1]
        assert pickle.loads(disk.load(key)) == 42
    finally:
        memo.install(previous)


def test_unpicklable_inputs_and_values_are_computed_not_remembered(tmp_path):
    disk = DiskMemo(tmp_path, code="d" * 64)
    previous = memo.installed()
    memo.install(disk)
    try:
        closure = lambda: None  # noqa: E731
        assert memo.key_of("test", (closure,)) is None
        calls = []
        for _ in range(2):
            assert memo.remember("test", (closure,), lambda: calls.append(1) or 7) == 7
        assert calls == [1, 1]
        value = memo.remember("test", "lock", lambda: calls.append(1) or (lambda: 3))
        assert value() == 3 and disk.saves == 0
    finally:
        memo.install(previous)


def test_sympy_inputs_are_keyed_by_meaning_not_by_term_order():
    import sympy as sp

    x, y = sp.symbols("x y")
    a = sp.Add(x, y * 2, evaluate=False)
    b = sp.Add(y * 2, x, evaluate=False)
    assert memo.key_of("t", (a,)) == memo.key_of("t", (b,))
    assert memo.key_of("t", (x + y,)) != memo.key_of("t", (x - y,))
    positive = sp.Symbol("x", positive=True)  # assumptions change what sympy proves: another key
    assert memo.key_of("t", (positive + y,)) != memo.key_of("t", (x + y,))
    # floats that print alike to 15 digits are other numbers: other keys
    assert sp.sstr(sp.Float(0.1) * x) == sp.sstr(sp.Float(0.1 + 2**-56) * x)
    assert memo.key_of("t", (sp.Float(0.1) * x,)) != memo.key_of("t", (sp.Float(0.1 + 2**-56) * x,))
    assert memo.key_of("t", (sp.Float(0.1) * x,)) == memo.key_of("t", (sp.Float(0.1) * x,))


def test_the_folder_is_pruned_least_recently_used_first(tmp_path):
    disk = DiskMemo(tmp_path, max_bytes=3 * 4096, code="e" * 64)  # each file: 4 KiB and its header
    for i in range(5):
        disk.save(f"k:{i}", bytes(4096))
        os.utime(disk.path(f"k:{i}"), (1000 + i, 1000 + i))
    disk.load("k:0")  # read: recently used again
    disk.prune()
    assert sorted(i for i in range(5) if disk.path(f"k:{i}").exists()) == [0, 4]


def test_a_folder_another_user_could_write_is_refused(tmp_path):
    """Its files are unpickled: a folder writable by group or others is not used (nothing remembered)."""
    from nonholonomic import memo as core_memo
    from workers.disk_memo import install_disk_memo

    open_folder = tmp_path / "open"
    open_folder.mkdir()
    os.chmod(open_folder, 0o777)
    with pytest.raises(PermissionError, match="writable by other users"):
        DiskMemo(open_folder, code="f" * 64)
    previous = core_memo.installed()
    try:
        assert install_disk_memo(str(open_folder)) is None and core_memo.installed() is previous
    finally:
        core_memo.install(previous)


def test_a_write_that_fails_leaves_no_partial_file(tmp_path, monkeypatch):
    disk = DiskMemo(tmp_path, code="g" * 64)

    def full(*_):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", full)
    disk.save("k", b"payload")
    assert list(tmp_path.iterdir()) == [] and disk.load("k") is None
