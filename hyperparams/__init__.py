"""The zoo YAML files (one per algorithm, keyed by env id): package data of ``sb3_denfac.hyperparams``."""
