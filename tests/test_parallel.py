"""Linear algebra stays on one thread inside a reconstruction and the workers it forks."""

import multiprocessing

import numpy as np
from threadpoolctl import threadpool_info

from wholearm_tools._parallel import one_blas_thread, worker_pool


def _blas_threads() -> list[int]:
    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]


def test_one_blas_thread_holds_in_forked_workers_and_is_undone_after():
    np.ones((2, 2)) @ np.ones((2, 2))  # numpy's BLAS is loaded
    before = _blas_threads()
    assert before
    with one_blas_thread():
        assert set(_blas_threads()) == {1}
        if "fork" in multiprocessing.get_all_start_methods():
            with worker_pool(2) as pool:
                assert pool is not None
                assert set(pool.submit(_blas_threads).result()) == {1}
    assert _blas_threads() == before
