"""GL calls that release the GIL while the driver works (ctypes, through EGL).

:class:`~speed_sign_detector.detection.voting_gl.GLVoter` dispatches its compute passes
and waits for them through these calls, so that other Python threads of the process keep
running meanwhile.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from speed_sign_detector.errors import DetectorError

if TYPE_CHECKING:
    import moderngl

__all__ = ['UnlockedGLCalls']


class UnlockedGLCalls:
    """The GL calls that wait for the driver, made so that other Python threads can run.

    moderngl keeps the GIL during its GL calls. On llvmpipe a compute dispatch returns
    only when the CPU threads of the driver have done the work, so a moderngl dispatch
    stops every other thread of the process (a node's executor, the recognition of the
    previous frame) for its whole duration. ctypes releases the GIL around foreign calls,
    so these functions, resolved with ``eglGetProcAddress`` for the context current on
    the calling thread, let them run. Programs and buffers are moderngl objects
    (``.glo`` is their GL name); moderngl binds its own program and buffers again before
    each of its calls, so mixing the two is safe.

    Raises:
        DetectorError: when libEGL or one of the functions cannot be found.
    """

    _DISPATCH_INDIRECT_BUFFER = 0x90EE
    _ALL_BARRIER_BITS = 0xFFFFFFFF

    def __init__(self) -> None:
        import ctypes
        import ctypes.util

        name = ctypes.util.find_library('EGL') or 'libEGL.so.1'
        try:
            egl = ctypes.CDLL(name)
        except OSError as err:
            raise DetectorError(f'cannot load {name} for GL calls: {err}') from err
        lookup = egl.eglGetProcAddress
        lookup.restype = ctypes.c_void_p
        lookup.argtypes = [ctypes.c_char_p]

        def function(gl_name: str, *argtypes: type) -> Callable[..., None]:
            address = lookup(gl_name.encode())
            if not address:
                raise DetectorError(f'eglGetProcAddress found no {gl_name}')
            return ctypes.CFUNCTYPE(None, *argtypes)(address)

        uint = ctypes.c_uint
        self._use_program = function('glUseProgram', uint)
        self._dispatch = function('glDispatchCompute', uint, uint, uint)
        self._dispatch_indirect = function('glDispatchComputeIndirect', ctypes.c_ssize_t)
        self._bind_buffer = function('glBindBuffer', uint, uint)
        self._memory_barrier = function('glMemoryBarrier', uint)
        self.finish = function('glFinish')
        """Wait until the GL work queued so far is done."""

    def run(self, shader: moderngl.ComputeShader, groups_x: int, groups_y: int) -> None:
        """Dispatch ``groups_x x groups_y`` work groups of a compute shader."""
        self._use_program(shader.glo)
        self._dispatch(groups_x, groups_y, 1)

    def run_indirect(self, shader: moderngl.ComputeShader, command: moderngl.Buffer) -> None:
        """Dispatch a compute shader with the group counts held in ``command`` (3 uint)."""
        self._use_program(shader.glo)
        self._bind_buffer(self._DISPATCH_INDIRECT_BUFFER, command.glo)
        self._dispatch_indirect(0)

    def memory_barrier(self) -> None:
        """Make the writes of earlier dispatches visible to later GL commands."""
        self._memory_barrier(self._ALL_BARRIER_BITS)
