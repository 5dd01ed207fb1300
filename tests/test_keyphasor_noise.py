"""A keyphasor with noise on it, as a real proximity probe's pulse has: the edges are found
with hysteresis (a Schmitt trigger), one a turn, where a clean pulse's would be; the batch
path and the monitor's chunked tracker find the same ones."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rotor_env.measurements import keyphasor
from rotor_env.measurements.keyphasor import KeyphasorError, KeyphasorTracker, pulse_edges


@pytest.fixture(scope="module")
def clean(tmp_path_factory, rig_records):
    """A run-up's keyphasor (a 5 V notch, its edge a sample or two wide) at 5 kHz."""
    _, cols, _ = rig_records.one_plane_run(tmp_path_factory.mktemp("kp"), rpm_per_s=400.0, seed=2)
    # an edge over a few samples, as a probe tip crossing a notch gives (first-order lag)
    kp = np.asarray(cols["kp"], dtype=float)
    slow = np.empty_like(kp)
    acc = kp[0]
    for i, v in enumerate(kp):
        acc += 0.5 * (v - acc)
        slow[i] = acc
    return np.asarray(cols["t"], dtype=float), slow


def _crossings(t, x, thr):
    """The reference: the signal's falling crossings of ``thr`` (a notch), linear between samples."""
    k = np.nonzero((x[:-1] >= thr) & (x[1:] < thr))[0]
    return t[k] + (thr - x[k]) / (x[k + 1] - x[k]) * (t[k + 1] - t[k])


def test_clean_edges_are_the_thresholds_crossings(clean):
    t, kp = clean
    lo, hi = np.percentile(kp, [0.1, 99.9])
    ref = _crossings(t, kp, 0.5 * (lo + hi))
    got = pulse_edges(t, kp)
    assert len(got) == len(ref) > 100
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12)


@pytest.mark.parametrize(("noise_v", "seed"), [(0.3, 0), (0.3, 1), (0.6, 2)])
def test_a_noisy_keyphasor_gives_one_edge_a_turn_where_the_clean_one_is(clean, noise_v, seed):
    t, kp = clean
    noisy = kp + np.random.default_rng(seed).normal(0.0, noise_v, kp.size)
    clean_edges = pulse_edges(t, kp)
    got = pulse_edges(t, noisy)
    assert len(got) == len(clean_edges)
    dt = float(t[1] - t[0])
    err = (got - clean_edges) / dt  # samples
    # the crossing jitters by the noise over the edge's slope (1.6 V a sample at the threshold)
    thr = 0.5 * sum(np.percentile(kp, [0.1, 99.9]))
    k = np.nonzero((kp[:-1] >= thr) & (kp[1:] < thr))[0]
    jitter = noise_v / float(np.median(np.abs(kp[k + 1] - kp[k])))
    assert np.std(err) < 1.5 * jitter, (np.std(err), jitter)
    # and is moved alike at every edge by the threshold the noisy levels give (0.1 / 99.9 %
    # points: a tenth to a fifth of a sample here, a fraction of a milliradian at top speed)
    assert abs(np.mean(err)) < 0.3


def test_without_the_hysteresis_such_noise_is_read_as_extra_pulses(clean):
    """The reader before the trigger had hysteresis: 0.45 V on the 5 V notch chattered at the
    threshold (0.3 V: two records in ten), and such records were refused as irregular; with
    it none is."""
    t, kp = clean
    refused = 0
    for seed in range(5):
        noisy = kp + np.random.default_rng(100 + seed).normal(0.0, 0.45, kp.size)
        assert len(pulse_edges(t, noisy)) == len(pulse_edges(t, kp))
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(keyphasor, "HYSTERESIS", 0.0)
            mp.setattr(keyphasor, "drop_spurious_pulses", lambda e: (e, []))  # nor the spikes' repair
            try:
                pulse_edges(t, noisy)
            except KeyphasorError as exc:
                assert "irregular pulses" in str(exc)
                refused += 1
    assert refused >= 4


def _track(t, signal, chunk):
    """``signal`` through the monitor's tracker in chunks of ``chunk`` samples: the tracker,
    and the times and angles it handed out."""
    tracker = KeyphasorTracker(where="kp")
    lines = np.arange(len(t)) + 2
    out_t, out_phi = [], []
    for lo in range(0, len(t), chunk):
        sl = slice(lo, lo + chunk)
        got = tracker.push(t[sl], signal[sl], signal[sl], lines[sl])
        out_t.append(got[0])
        out_phi.append(got[1])
    got = tracker.finish()
    return tracker, np.concatenate([*out_t, got[0]]), np.concatenate([*out_phi, got[1]])


def _turn_times(ts, phis, edges):
    """Where the handed-out angle passes each whole turn, and the edge of ``edges`` each is
    (the tracker's spline goes through its own edges)."""
    turns = np.arange(math.ceil(phis[0] / (2 * math.pi)), math.floor(phis[-1] / (2 * math.pi)) + 1)
    at = np.interp(2 * math.pi * turns, phis, ts)
    n = np.searchsorted(edges, at[0] - 0.5 * np.median(np.diff(edges))) - turns[0]  # the first edge's number
    keep = (turns + n >= 0) & (turns + n < len(edges))
    assert keep.sum() > 0.9 * len(edges)
    return at[keep], edges[turns[keep] + n]


@pytest.mark.parametrize("chunk", [97, 1000, 65536])
def test_the_chunked_tracker_finds_the_batch_edges_on_a_noisy_keyphasor(clean, chunk):
    t, kp = clean
    noisy = kp + np.random.default_rng(5).normal(0.0, 0.4, kp.size)
    batch = pulse_edges(t, noisy)
    tracker, ts, phis = _track(t, noisy, chunk)
    assert tracker.edges_seen == len(batch)
    # the tracker's threshold is fixed from the first 2048 samples, the batch's from all: with
    # noise they differ a little, and so do the edges (a third of a sample at the start, a
    # twentieth later)
    at, ref = _turn_times(ts, phis, batch)
    assert np.abs(at - ref).max() < 0.5 * (t[1] - t[0])


def _spiked(t, kp, where):
    """``kp`` with one-sample spikes to the notch's level at the sample nearest each time of ``where``."""
    out = kp.copy()
    for w in where:
        out[int(np.searchsorted(t, w))] = -5.0
    return out


def test_a_spike_on_the_keyphasor_is_dropped_and_said(clean):
    """Interference on the keyphasor: a spike in the middle of a revolution, and a ringing edge
    (a second trigger just after a notch) -- each splits a revolution in two; dropped, the
    edges are the clean record's, and the note names the time and the line."""
    t, kp = clean
    edges = pulse_edges(t, kp)
    mid = 0.5 * (edges[60] + edges[61])
    ring = edges[120] + 0.15 * (edges[121] - edges[120])
    notes: list[str] = []
    got = pulse_edges(t, _spiked(t, kp, [mid, ring]), lines=np.arange(len(t)) + 2, notes=notes)
    # (the spikes' two samples move the 0.1 % level, and the threshold with it, by a hair)
    np.testing.assert_allclose(got, edges, rtol=0, atol=1e-9)
    assert len(notes) == 1 and notes[0].startswith("2 spurious keyphasor pulses dropped (t = ")
    line = int(np.searchsorted(t, mid)) + 2
    assert f"line {line}" in notes[0]


def test_many_spikes_are_a_keyphasor_to_look_at(clean):
    """More spurious pulses than one in fifty: refused, as before."""
    t, kp = clean
    edges = pulse_edges(t, kp)
    mids = 0.5 * (edges[10:-10:8] + edges[11:-9:8])  # every 8th revolution
    with pytest.raises(KeyphasorError, match="irregular pulses"):
        pulse_edges(t, _spiked(t, kp, mids))


@pytest.mark.parametrize("chunk", [97, 4096])
def test_the_chunked_tracker_drops_the_same_spike(clean, chunk):
    t, kp = clean
    edges = pulse_edges(t, kp)
    mid = 0.5 * (edges[60] + edges[61])
    spiked = _spiked(t, kp, [mid])
    tracker, ts, phis = _track(t, spiked, chunk)
    assert tracker.edges_seen == len(edges)
    assert len(tracker.dropped) == 1 and abs(tracker.dropped[0][0] - mid) < 2 * (t[1] - t[0])
    # the handed-out angle is the clean record's: a whole turn at each clean edge
    at, ref = _turn_times(ts, phis, edges)
    np.testing.assert_allclose(at, ref, rtol=0, atol=0.05 * (t[1] - t[0]))


def test_the_record_and_the_monitors_stream_say_the_spike(tmp_path, rig_records):
    """Through the readers a user meets: ``load_waveforms`` (diagnose) and ``RigStream`` (monitor)."""
    from rotor_env.measurements.rig_stream import RigStream
    from rotor_env.measurements.waveforms import load_waveforms

    rig, cols, _ = rig_records.one_plane_run(tmp_path, rpm=(300.0, 2400.0), rpm_per_s=600.0, seed=4)
    edges = pulse_edges(cols["t"], cols["kp"])
    k = int(np.searchsorted(cols["t"], 0.5 * (edges[30] + edges[31])))
    cols["kp"][k] = -5.0
    path = rig_records.write_csv(tmp_path / "run.csv", cols)
    crossing = 0.5 * (cols["t"][k - 1] + cols["t"][k])  # the spike's edge: halfway into it
    said = f"1 spurious keyphasor pulse dropped (t = {crossing:.6g} s, line {k + 2})"
    assert any(n.startswith(said) for n in load_waveforms(path, rig).notes)
    stream = RigStream(path, rig, 1650.0, chunk_bytes=8192)
    for _ in stream:
        pass
    assert any(n.startswith(said) for n in stream.notes), stream.notes
