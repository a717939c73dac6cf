"""The DENFAC ablation study: its journal, record scripts and the prototypes' data (README.md)."""
