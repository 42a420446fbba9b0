"""Long takes are filled in overlapping pieces: the same result as filling each piece alone,
memory bounded by the piece length (the 72,000-frame run is tools/load_test.py)."""

from dataclasses import replace

import numpy as np
import pytest

from mocap_gapfill.core.evaluate import punch_gaps, rmse_mm, with_gaps
from mocap_gapfill.core.io import read_motion
from mocap_gapfill.core.kb import build_kb
from mocap_gapfill.core.recover import KnnSettings, fill_knn, pieces

FAST = KnnSettings(k=64, max_iterations=5, device="numpy")


@pytest.fixture(scope="module")
def kb(data_dir):
    return build_kb([data_dir / "hdm05/c3d"], stride=4)


@pytest.fixture(scope="module")
def take(data_dir):
    """CMU 135_02 (markers, no gaps of its own), first 1,500 frames, 20 % hidden."""
    truth = read_motion(data_dir / "cmu/c3d/135_02.c3d").frame_range(0, 1500)
    hidden = punch_gaps(truth.n_frames, truth.n_points, "markers", 0.2, np.random.default_rng(3))
    return truth, hidden, with_gaps(truth, hidden)


@pytest.mark.parametrize("n,size,overlap", [(100, 50, 50), (1500, 400, 100), (1501, 400, 100),
                                            (72000, 6000, 600), (6601, 6000, 600)])
def test_pieces_cover_the_take_and_share_the_overlap(n, size, overlap):
    ranges = pieces(n, size, overlap)
    assert ranges[0][0] == 0 and ranges[-1][1] == n
    assert all(b - a <= size + overlap for a, b in ranges)
    assert all(b1 - a2 == overlap for (_, b1), (a2, _) in zip(ranges, ranges[1:]))
    assert len(ranges) == (1 if n <= size + overlap else -(-(n - overlap) // size))


def test_a_long_take_equals_its_pieces_filled_alone(kb, take):
    truth, hidden, gapped = take
    chunked = replace(FAST, segment_frames=400, segment_overlap=100)
    ranges = pieces(gapped.n_frames, 400, 100)
    assert len(ranges) == 4
    whole = fill_knn(gapped, kb, chunked)
    observed = ~gapped.missing
    assert np.array_equal(whole.positions[observed], truth.positions[observed])
    assert not np.isnan(whole.positions).any() and whole.filled[hidden].all()
    parts = [fill_knn(gapped.frame_range(a, b), kb, FAST).positions for a, b in ranges]
    for i, (a, b) in enumerate(ranges):
        lo = ranges[i - 1][1] if i else a
        hi = ranges[i + 1][0] if i + 1 < len(ranges) else b
        assert np.array_equal(whole.positions[lo:hi], parts[i][lo - a:hi - a])
        if i:  # the shared frames fade from the previous piece's fill into this one's
            prev = parts[i - 1][a - ranges[i - 1][0]:]
            got, mine = whole.positions[a:lo], parts[i][:lo - a]
            assert (got >= np.fmin(prev, mine) - 1e-9).all() and (got <= np.fmax(prev, mine) + 1e-9).all()
            assert np.allclose(got[0], prev[0], atol=0.01) and np.allclose(got[-1], mine[-1], atol=0.01)
    # pieces cost little accuracy: within 10 % of filling the 1,500 frames at once
    at_once = fill_knn(gapped, kb, FAST)
    assert rmse_mm(whole, truth, hidden) < 1.1 * rmse_mm(at_once, truth, hidden)


def test_a_piece_with_nothing_observed_is_left_unfilled(kb, take):
    truth, hidden, gapped = take
    dark = gapped.positions.copy()
    dark[500:1000] = np.nan  # every marker lost for 500 frames: pieces 2 and 3 see nothing
    messages = []
    out = fill_knn(gapped.replace(positions=dark), kb,
                   replace(FAST, segment_frames=200, segment_overlap=50), report=messages.append)
    assert any("every sample is missing, left unfilled" in m for m in messages)
    assert len(messages) == len(set(messages))  # each message once, not once per piece
    lit = np.zeros(len(dark), bool)  # frames of a piece that sees something
    for a, b in pieces(len(dark), 200, 50):
        lit[a:b] |= not np.isnan(dark[a:b]).all()
    assert not lit[600:900].any() and lit[:550].all() and lit[950:].all()
    assert (np.isnan(out.positions[..., 0]) == ~lit[:, None]).all()
