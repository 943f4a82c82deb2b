"""The project's error types: one base, so a caller (``cli.main``) can tell our refusals from bugs.

=====================  ==================================================  =========
error                  raised when                                          exit code
=====================  ==================================================  =========
FacepuppetError        base of the project's own errors                     2
TablesError            a tables file is missing, corrupt or does not fit     2
InputFileError         any other input file (recording, capture, mesh,      2
                       audio, config) is unreadable or malformed
NotFittedError         a fitter is used before ``fit``                      2
GLUnavailable          no OpenGL context (no display, no EGL)               3
=====================  ==================================================  =========

``cli.main`` maps these (and ValueError, FileNotFoundError, PermissionError, OSError from a
bind) to exit codes in one place; commands raise, they do not print errors and return codes.
"""

from __future__ import annotations


class FacepuppetError(Exception):
    """Base of facepuppet's own errors; the message names the file or option and what was wrong."""


class NotFittedError(FacepuppetError, ValueError):
    """A fitter's ``predict``/``transform``/``export`` was called before ``fit``."""


class InputFileError(FacepuppetError, ValueError):
    """An input file (recording, marker capture, mesh, WAV, config) cannot be read; the message names it.

    A ValueError too, so callers that caught the readers' ValueErrors still do.
    """
