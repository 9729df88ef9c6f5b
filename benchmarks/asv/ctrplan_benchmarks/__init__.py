"""asv benchmarks of ctrplan (``benchmarks.py``)."""
