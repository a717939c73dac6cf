"""Traces of single ablation runs (journal.md, section 25)."""
