"""Test helpers shared across the suite: small characters and actors, OSC/UDP senders, gesture databases."""
