"""Many replays as one batch (takes x characters), and a batch run compared with an earlier one."""
