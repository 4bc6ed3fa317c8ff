"""softplc.latency.statistics against vectors computed by hand."""

from __future__ import annotations

import math
import statistics as pystats

import pytest

from softplc.latency.statistics import histogram, nice_width, share_at_most, summarize


def test_table8_fields_by_hand():
    # 10, 10, 20, 30, 50: sum 120, mean 24; squared deviations 196+196+16+36+676 = 1120,
    # sample variance 1120 / 4 = 280, std = sqrt(280) = 16.7332.
    result = summarize([10, 10, 20, 30, 50])
    assert result.samples == 5
    assert result.mean == pytest.approx(24.0)
    assert result.std == pytest.approx(math.sqrt(280.0))
    assert result.mean_plus_std == pytest.approx(24.0 + math.sqrt(280.0))
    assert result.best == 10 and result.worst == 50
    # ≤ 20: 10, 10, 20 (the boundary is in); 20-40: 30; > 40: 50.
    assert (result.share_le_20, result.share_20_40, result.share_gt_40) == pytest.approx((60.0, 20.0, 20.0))


def test_percentiles_interpolate_linearly():
    # Sorted 10, 10, 20, 30, 50; rank (n-1)q: p50 → 2 → 20; p95 → 3.8 → 30 + 0.8·20 = 46;
    # p99 → 3.96 → 49.2; p99.9 → 3.996 → 49.92.
    result = summarize([30, 10, 50, 20, 10])
    assert result.percentiles == pytest.approx({"p50": 20.0, "p95": 46.0, "p99": 49.2, "p999": 49.92})


def test_category_boundaries():
    result = summarize([20.0, 20.0001, 40.0, 40.5])
    assert (result.share_le_20, result.share_20_40, result.share_gt_40) == pytest.approx((25.0, 50.0, 25.0))


def test_std_matches_the_n_minus_1_formula():
    values = [15.0, 10.0, 10.0, 20.0, 120.0, 10.0, 30.0]
    result = summarize(values)
    assert result.std == pytest.approx(pystats.stdev(values))
    assert result.std != pytest.approx(pystats.pstdev(values))


def test_one_sample_has_no_std_and_empty_has_nothing():
    one = summarize([7.0])
    assert one.samples == 1 and one.mean == 7.0 and one.std is None and one.mean_plus_std is None
    assert one.share_le_20 == 100.0
    empty = summarize([])
    assert empty.samples == 0 and empty.mean is None and empty.worst is None and empty.histogram is None


def test_nan_is_refused():
    with pytest.raises(ValueError, match="finite"):
        summarize([1.0, float("nan")])


def test_histogram_by_hand():
    result = histogram([10, 10, 20, 30, 50], 10.0)
    # Bins from floor(min / width) · width = 10: [10,20) 2, [20,30) 1, [30,40) 1, [40,50) 0, [50,60) 1.
    assert result.edges == [10, 20, 30, 40, 50, 60]
    assert result.counts == [2, 1, 1, 0, 1]
    assert result.overflow_from is None
    assert result.rows()[0] == ("10–20", 2)


def test_histogram_tail_goes_to_an_overflow_bin():
    result = histogram([1.0, 2.0, 3.0, 1000.0], 1.0, max_bins=10)
    assert len(result.counts) == 10 and sum(result.counts) == 4
    assert result.counts[:3] == [1, 1, 1] and result.counts[-1] == 1
    assert result.overflow_from == 10.0
    assert result.rows()[-1] == ("≥ 10", 1)


def test_nice_width():
    assert nice_width(49.92, 60) == 1.0
    assert nice_width(5.0, 60) == 0.1
    assert nice_width(10.0, 60) == 0.2
    assert nice_width(250.0, 60) == 5.0


def test_summary_histogram_chooses_a_width():
    result = summarize([1.2, 1.3, 1.25, 2.8, 9.9])
    assert result.histogram is not None
    assert result.histogram.width == 0.2
    assert sum(result.histogram.counts) == 5


def test_share_at_most():
    assert share_at_most([10, 10, 20, 30], 10) == 50.0
    assert share_at_most([], 10) is None
