"""``facepuppet bench``: the benchmark registry and the runtime's benchmarks."""
