"""facepuppet: realtime facial puppetry.

``facepuppet.runtime`` is the live part (sources, frame loop, renderer) and
``facepuppet.offline`` the training part; the runtime never imports offline.
"""

__version__ = "0.1.0"
