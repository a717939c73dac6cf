"""Test-wide settings: one torch thread per test process (CI runs pytest -n 2 on a 2-core machine)."""

import torch as th

th.set_num_threads(1)
