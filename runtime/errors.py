"""The project's error types: one base, so that ``cli.main`` can tell our refusals from bugs.

A refusal (a bad option, a file that cannot be used, a missing device) is a :class:`FacepuppetError` whose
message names the option or file and what was wrong; ``cli.main`` prints it in one line,
``facepuppet COMMAND: error: MESSAGE``, and exits 2 (3 for no OpenGL, 1 for a run whose recording failed), as it
does for an ``OSError`` (a file
missing or unreadable, an address that cannot be bound). Any other exception, a plain ``ValueError`` from NumPy
included, is a bug in facepuppet: ``cli.main`` lets it through, Python prints its traceback and exits 1.
``FACEPUPPET_DEBUG=1`` in the environment shows the traceback of a refusal too.

So a check of something a user gives (an option value, a file's content, tables that must fit together, data a
fit cannot use) raises one of these; a check of how our own code calls a function stays a ``ValueError`` or
``TypeError``. Readers catch the low-level errors of the libraries they use on damaged input (``struct.error``,
``zlib.error``, ``UnicodeDecodeError``, NumPy's ``ValueError``) at their boundary and raise their own, naming
the file.

======================  ==============================================  ===================================  ====
error                   raised when                                     module                               exit
======================  ==============================================  ===================================  ====
FacepuppetError         base of the project's own errors                errors                               2
UsageError              an option, or a combination of options and the  errors                               2
                        inputs they name, cannot be used as given (a
                        value out of range, tables that do not fit
                        together, more than the data can fit)
InputFileError          an input file (recording, capture, mesh, WAV,   errors; subclasses: LiveConfigError,  2
                        config, glTF, OBJ, JSON) is unreadable,         GltfError, CaptureError, ObjError,
                        malformed or cannot be used as it is            SpeechInputError
TablesError             a tables file is missing, corrupt or does not   tables                               2
                        fit
OutputError             an output cannot be written as asked            outputs                              2
MappingError            a ``[mapping]`` names what the character lacks  expressions                          2
VideoError              ``--video`` cannot be written as asked          live.video_out                       2
NotFittedError          a fitter is used before ``fit``                 errors                               2
FaceError               perfect sync finds no face on the character     offline.perfect_sync.face            2
ExportError             a glTF / VRM export cannot be written as asked  offline.io.gltf.write_state          2
GltfProblems            check-gltf found problems in the file           offline.io.gltf_commands             2
AudioUnavailable        no audio device or library                      inputs.audio                         2
PanelUnavailable        the panel's extra (imgui-bundle) is missing     panel                                2
ShaderError             a shader does not compile or link here          render.shader_loader                 2
GLUnavailable           no OpenGL context (no display, no EGL)          render.gl_context                    3
RecordingFailed         a run's recording could not be written to its   errors                               1
                        end (disk full, the file-size limit); the run
                        stopped, the file keeps what was written
(any other exception)   a bug in facepuppet: its traceback shows        (Python)                             1
======================  ==============================================  ===================================  ====

Each subclass is a ``ValueError`` (or a ``RuntimeError`` for a missing device or library) too, so code that caught
those still does. ``tests/runtime/test_cli.py`` checks that every exception class of ``runtime`` and
``offline`` is one of these, but for three that never leave their module (``gltf_check._Stop``,
``inputs.counted.Dropped``, ``inputs.udp_channel.ChannelError``).
"""

from __future__ import annotations


class FacepuppetError(Exception):
    """Base of facepuppet's own errors; the message names the file or option and what was wrong."""


class UsageError(FacepuppetError, ValueError):
    """An option, or a combination of options and the inputs they name, cannot be used as given; the message
    names the option (or the inputs) and what would do."""


class NotFittedError(FacepuppetError, ValueError):
    """A fitter's ``predict``/``transform``/``export`` was called before ``fit``."""


class InputFileError(FacepuppetError, ValueError):
    """An input file (recording, marker capture, mesh, WAV, config) cannot be read or used; the message names it
    (or the field of it that is wrong).

    A ValueError too, so callers that caught the readers' ValueErrors still do.
    """


class RecordingFailed(FacepuppetError, RuntimeError):
    """A run's recording could not be written to its end (disk full, the file-size limit): the run stopped
    there; the message names the file and what it keeps. Exit 1: the run did not do what was asked, though
    nothing the user gave was wrong."""
