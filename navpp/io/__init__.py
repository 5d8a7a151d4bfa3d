"""Readers and writers: logs in, ``Recording`` out; ``Solution`` in, files out (no filter knowledge)."""
