"""Issue 26, item 7: the streaming accumulator's state. A copy is a copy, a checkpoint (pickle or
``save``/``load``) resumes a stream bit for bit and refuses what it cannot read by name, and a
sample whose products would overflow is refused at ``push`` without harming the accumulator."""

import copy
import pickle
import warnings

import numpy as np
import pytest

import modaluq

SETTINGS = dict(n_outputs=3, n_inputs=1, block_rows=8, block_length=500)


@pytest.fixture(scope="module")
def sim():
    return modaluq.simulate(8_000, seed=5)


def _accumulator(**kw):
    return modaluq.CovarianceAccumulator(**dict(SETTINGS, **kw))


def _push(acc, sim, start, stop, step=700):
    for s in range(start, stop, step):
        e = min(s + step, stop)
        acc.push(sim.y[s:e], sim.u[s:e])


def _identify(acc, sim):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", modaluq.ModalUQWarning)
        return acc.identify(fs=sim.fs, orders=[6, 8])


def assert_same_result(a, b):
    """Bit for bit: the covariances, the per-block covariances and the modes with their sigma."""
    for name in ("R1", "R2", "R3", "R4", "blocks", "channel_mean"):
        np.testing.assert_array_equal(getattr(a[0], name), getattr(b[0], name), err_msg=name)
    for order in (6, 8):
        ma, mb = a[1].at_order(order), b[1].at_order(order)
        for name in ("frequency_hz", "damping_ratio", "frequency_std", "damping_std"):
            np.testing.assert_array_equal(getattr(ma, name), getattr(mb, name), err_msg=f"{name} at order {order}")


def _outcome(acc, sim):
    return acc.covariances(), _identify(acc, sim)


@pytest.fixture(scope="module")
def uninterrupted(sim):
    acc = _accumulator()
    _push(acc, sim, 0, 3_500)
    _push(acc, sim, 3_500, 8_000)
    return _outcome(acc, sim)


# ------------------------------------------------------------------------------------ copies


@pytest.mark.parametrize("copier", [copy.copy, copy.deepcopy], ids=["copy", "deepcopy"])
def test_a_copy_has_its_own_state(sim, copier, uninterrupted):
    # Before: copy.copy shared the C++ state (pushing into the copy changed the original) and
    # deepcopy raised TypeError.
    acc = _accumulator()
    _push(acc, sim, 0, 3_500)
    twin = copier(acc)
    twin.push(sim.y[:1000] * 3.0, sim.u[:1000])  # other samples into the copy only
    assert acc.n_samples == 3_500 and twin.n_samples == 4_500
    _push(acc, sim, 3_500, 8_000)
    assert_same_result(_outcome(acc, sim), uninterrupted)


# ------------------------------------------------------------------------------- checkpoints


def test_pickle_resumes_the_stream_bit_for_bit(sim, uninterrupted):
    acc = _accumulator()
    _push(acc, sim, 0, 3_500)
    resumed = pickle.loads(pickle.dumps(acc))
    assert resumed.n_samples == 3_500 and resumed.block_length == 500
    _push(resumed, sim, 3_500, 8_000)
    assert_same_result(_outcome(resumed, sim), uninterrupted)


def test_pickle_of_an_empty_accumulator_and_a_span(sim):
    empty = pickle.loads(pickle.dumps(_accumulator()))
    assert empty.n_samples == 0
    # A span starting later keeps its first sample and still merges after the span before it.
    head, span = _accumulator(), _accumulator(first_sample=4_000)
    head.push(sim.y[:4_000], sim.u[:4_000])
    span.push(sim.y[4_000:], sim.u[4_000:])
    head.merge(pickle.loads(pickle.dumps(span)))
    whole = _accumulator()
    whole.push(sim.y[:4_000], sim.u[:4_000])
    tail = _accumulator(first_sample=4_000)
    tail.push(sim.y[4_000:], sim.u[4_000:])
    whole.merge(tail)
    np.testing.assert_array_equal(head.covariances().blocks, whole.covariances().blocks)


def test_save_and_load_resume_the_stream_bit_for_bit(sim, uninterrupted, tmp_path):
    acc = _accumulator()
    _push(acc, sim, 0, 3_500)
    path = tmp_path / "stream.ckpt"
    acc.save(path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["stream.ckpt"]  # no temporary left
    resumed = modaluq.CovarianceAccumulator.load(path, n_outputs=3, n_inputs=1, block_rows=8, block_length=500)
    _push(resumed, sim, 3_500, 8_000)
    assert_same_result(_outcome(resumed, sim), uninterrupted)
    with np.load(path, allow_pickle=False) as f:  # the documented layout
        assert str(f["format"]) == "modaluq.CovarianceAccumulator" and int(f["version"]) == 1
        assert int(f["block_length"]) == 500 and int(f["end_sample"]) == 3_500


def test_a_failed_save_leaves_the_previous_checkpoint(sim, tmp_path, monkeypatch):
    acc = _accumulator()
    _push(acc, sim, 0, 3_500)
    path = tmp_path / "stream.ckpt"
    acc.save(path)
    before = path.read_bytes()
    acc.push(sim.y[3_500:4_000], sim.u[3_500:4_000])

    def full_disk(fh, **arrays):
        fh.write(b"partial")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(np, "savez", full_disk)
    with pytest.raises(OSError, match=r"stream\.ckpt.*No space left"):
        acc.save(path)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["stream.ckpt"]


def _rewrite(path, out, **changes):
    with np.load(path, allow_pickle=False) as f:
        state = {k: f[k] for k in f.files}
    for k, v in changes.items():
        if v is None:
            del state[k]
        else:
            state[k] = v
    with open(out, "wb") as fh:
        np.savez(fh, **state)
    return out


def test_a_checkpoint_it_cannot_read_is_refused_by_name(sim, tmp_path):
    acc = _accumulator()
    _push(acc, sim, 0, 3_500)
    path = tmp_path / "good.npz"
    acc.save(path)
    load = modaluq.CovarianceAccumulator.load
    with pytest.raises(ValueError, match=r"version 2 .*reads version 1"):
        load(_rewrite(path, tmp_path / "v2.npz", version=np.array(2)))
    with pytest.raises(ValueError, match="not a CovarianceAccumulator checkpoint"):
        load(_rewrite(path, tmp_path / "other.npz", format=np.array("something else")))
    with pytest.raises(ValueError, match="block_sums"):
        load(_rewrite(path, tmp_path / "missing.npz", block_sums=None))
    # Arrays that do not fit the layout the checkpoint declares: the core names the array.
    with pytest.raises(ValueError, match=r"head has shape 4 x 15, expected 4 x 17 for 4 channels, block_rows"):
        load(_rewrite(path, tmp_path / "layout.npz", block_rows=np.array(9)))
    with pytest.raises(ValueError, match="block_count"):
        with np.load(path) as f:
            counts = f["block_count"].copy()
        counts[0] += 1
        load(_rewrite(path, tmp_path / "count.npz", block_count=counts))
    with pytest.raises(ValueError, match="tail"):
        with np.load(path) as f:
            tail = f["tail"].copy()
        tail[0, 0] = np.nan
        load(_rewrite(path, tmp_path / "nan.npz", tail=tail))
    (tmp_path / "text.npz").write_text("not a checkpoint")
    with pytest.raises(ValueError, match=r"text\.npz: not a CovarianceAccumulator checkpoint \(not an \.npz"):
        load(tmp_path / "text.npz")
    with pytest.raises(FileNotFoundError, match="absent.npz"):
        load(tmp_path / "absent.npz")
    # A checkpoint of other settings than the caller expects.
    with pytest.raises(ValueError, match=r"good\.npz.*block_rows is 8, expected 12"):
        load(path, block_rows=12)
    with pytest.raises(TypeError, match="unexpected"):
        load(path, n_blocks=12)
    # pickle goes through the same checks
    state = acc.__getstate__()
    state["version"] = 7
    with pytest.raises(ValueError, match="version 7"):
        _accumulator().__setstate__(state)


# ---------------------------------------------------------------------------- overflow at push


@pytest.mark.parametrize("where", ["y", "u"])
def test_a_sample_whose_products_would_overflow_is_refused_and_harms_nothing(sim, where):
    # Before: 1e200 was accepted and every later identify on the accumulator failed.
    clean = _accumulator()
    _push(clean, sim, 0, 3_000)
    _push(clean, sim, 3_000, 8_000)

    acc = _accumulator()
    _push(acc, sim, 0, 3_000)
    y, u = sim.y[3_000:4_000].copy(), sim.u[3_000:4_000].copy()
    if where == "y":
        y[123, 2] = 1e200
    else:
        u[123, 0] = -1e200
    channel = 2 if where == "y" else 0
    with pytest.raises(ValueError, match=rf"^{where}: sample 3123, channel {channel} is .*1e\+200.*not finite"):
        acc.push(y, u)
    assert acc.n_samples == 3_000
    _push(acc, sim, 3_000, 8_000)
    assert_same_result(_outcome(acc, sim), _outcome(clean, sim))


def test_the_magnitude_limit():
    acc = modaluq.CovarianceAccumulator(1, block_rows=2, block_length=4)
    acc.push(np.full(3, 1e60))  # at the limit: accepted
    with pytest.raises(ValueError, match="sample 3, channel 0"):
        acc.push(np.full(2, -1.0000001e60))
    assert acc.n_samples == 3
