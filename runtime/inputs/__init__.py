"""Live inputs: one adapter per tracker protocol, the strict OSC reader, the UDP receivers, audio level."""
