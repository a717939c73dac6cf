"""Torch threads inside ``learn()``: the study behind DENFAC's ``torch_threads=1`` default (README.md)."""
