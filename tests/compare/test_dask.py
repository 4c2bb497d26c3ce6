"""The same comparison on a local Dask cluster gives the same rows as local processes."""

from __future__ import annotations

from pathlib import Path

import pytest

from wholearm_tools.compare import ComparisonTable, compare_runs

distributed = pytest.importorskip("distributed")


def test_dask_cluster_equals_local(local_table: ComparisonTable,
                                   logs: dict[str, Path], Bs: tuple[float, ...]) -> None:
    paths = [logs["missing"], logs["a"]]
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        table = compare_runs(paths, Bs, scheduler=cluster.scheduler_address)
        names = {p.name for p in paths}
        expected = [r for r in local_table.results() if r["log"] in names]
        assert len(expected) == 2 * len(Bs)
        assert table.results() == expected
        assert all(r["wall_time_s"] > 0 for r in table if r["status"] != "error")
        # a Client works too (and is left open for its owner)
        with distributed.Client(cluster) as client:
            small = compare_runs([logs["garbage"]], [0.05], scheduler=client)
            assert client.status == "running"
        assert small.rows[0]["status"] == "error"
        assert "garbage.mcap" in small.rows[0]["error"]
