"""The memory estimate counts the program itself where a run's peak is compared with it,
and not where it is compared with the memory left beside the program (issue 20)."""

from __future__ import annotations

import numpy as np

from nlosfw.pipeline.budget import check_memory, estimate_memory, memory_summary, process_memory

CONFIG = {"scene": {"wall": {"resolution": [16, 16]}, "time": {"bins": 512}},
          "transform": {"name": "fft", "n_frequencies": 21}, "model": {"name": "interp"},
          "reconstruction": {"n_depths": 4}}


def test_process_memory_grows_with_an_array_this_process_holds():
    before = process_memory()
    block = np.ones(50_000_000 // 8)                 # 50 MB, touched
    after = process_memory()
    assert before > 10_000_000                        # Python and numpy at least
    assert after - before >= 0.9 * block.nbytes


def test_the_program_is_a_part_of_the_estimate_only_when_asked():
    arrays = estimate_memory(CONFIG)
    with_program = estimate_memory(CONFIG, program=True)
    assert [p.what for p in with_program] == [p.what for p in arrays] + ["the program"]
    assert with_program[-1].nbytes > 10_000_000
    assert "the program" in memory_summary(CONFIG)
    # the memory available is what is left beside the program: the check leaves it out
    check_memory(CONFIG, available=int(sum(p.nbytes for p in arrays)) + 1)
