"""Cost and soak studies around the suites: the cost plan of a sweep, throughput on a machine, the update's cost,
a long soak run, slow envs, the Acrobot's horizon. Each is its own ``python -m benchmarks.studies.<module>``.
"""
