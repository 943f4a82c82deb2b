"""The project's error types: one base, so that ``cli.main`` can tell our refusals from bugs.

A refusal (a bad option, a file that cannot be used, a missing device) is a :class:`FacepuppetError` whose
message names the option or file and what was wrong; ``cli.main`` prints it in one line and exits 2 (3 for
no OpenGL). Any other exception is a bug in facepuppet: ``cli.main`` lets its traceback show.
``FACEPUPPET_DEBUG=1`` shows the traceback of a refusal too.

======================  ==============================================  ===================================  ====
error                   raised when                                     module                               exit
======================  ==============================================  ===================================  ====
FacepuppetError         base of the project's own errors                errors                               2
UsageError              an option, or a combination of options, cannot  errors                               2
                        be used as given
InputFileError          an input file (recording, capture, mesh, WAV,   errors; subclasses: LiveConfigError,  2
                        config, glTF, OBJ) is unreadable or malformed   GltfError, CaptureError, ObjError,
                                                                        SpeechInputError
TablesError             a tables file is missing, corrupt or does not   tables                               2
                        fit
OutputError             an output cannot be written as asked            outputs                              2
MappingError            a ``[mapping]`` names what the character lacks  expressions                          2
VideoError              ``--video`` cannot be written as asked          live.video_out                       2
NotFittedError          a fitter is used before ``fit``                 errors                               2
FaceError, ExportError  perfect sync finds no face; an export cannot    offline.perfect_sync.face,           2
GltfProblems            be written; check-gltf found problems           offline.io.gltf_export / commands
AudioUnavailable        no audio device or library                      inputs.audio                         2
PanelUnavailable        the panel's extra (imgui-bundle) is missing     panel                                2
ShaderError             a shader does not compile or link here          render.shader_loader                 2
GLUnavailable           no OpenGL context (no display, no EGL)          render.gl_context                    3
======================  ==============================================  ===================================  ====

Most are ``ValueError`` (or ``RuntimeError``) too, so code that caught those still does.
"""

from __future__ import annotations


class FacepuppetError(Exception):
    """Base of facepuppet's own errors; the message names the file or option and what was wrong."""


class UsageError(FacepuppetError, ValueError):
    """An option, or a combination of options, cannot be used as given; the message names the option."""


class NotFittedError(FacepuppetError, ValueError):
    """A fitter's ``predict``/``transform``/``export`` was called before ``fit``."""


class InputFileError(FacepuppetError, ValueError):
    """An input file (recording, marker capture, mesh, WAV, config) cannot be read; the message names it.

    A ValueError too, so callers that caught the readers' ValueErrors still do.
    """
