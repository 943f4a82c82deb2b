"""The voice: fitting the table that turns speech into ARKit mouth channels, its curves and its benchmark."""
