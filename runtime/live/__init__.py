"""The live frame loop and the stages of the per-frame chain, their config, timing and statistics."""
