"""The voice: causal log-mel features, the learned mouth table and its run-time sources and stage."""
