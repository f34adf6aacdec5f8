"""Files named by untrusted parameters: inside allowed directories, bounded, never quoted.

Anyone on a ROS graph can set a node's parameters, so a parameter that names a file
(a model, a compensation table, a trajectory table) is untrusted input.  Three rules
(issue 24, "safe on a real axis"):

* the path must resolve (symbolic links followed) inside one of the allowed
  directories; anything outside is refused *without being opened*;
* only a regular file under a size bound is read: a FIFO, a device or a socket is
  refused before any read (opened non-blocking, checked with ``fstat`` on the open
  descriptor, so a file swapped for a FIFO after the check cannot block the node);
* a rejection reason names the parameter, the path and the rule broken, never the
  file's content (a parser's own message can quote a line: :func:`parse_untrusted`
  replaces it by its category).

Core module: no rclpy; the nodes call it from their parameter callbacks.
"""
from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import Callable, Sequence, TypeVar

from motor_comp.errors import ParameterError

#: largest file a parameter may name [bytes]: a model file is a few kB, a position or
#: trajectory table of 10 minutes at 1 kHz a few MB
MAX_BYTES = 16 * 2**20

T = TypeVar('T')


def package_config_dir() -> Path:
    """Return the package's own ``config/`` directory (plant defaults, node parameters)."""
    return Path(__file__).resolve().parent / 'config'


def default_dirs() -> tuple[Path, ...]:
    """Return the default allowed directories: the working directory and ``config/``."""
    return (Path.cwd().resolve(), package_config_dir())


def parse_dirs(text: str) -> tuple[Path, ...]:
    """Return the allowed directories of a ``model_dir`` parameter (``:``-separated)."""
    parts = [p for p in str(text).split(os.pathsep) if p.strip()]
    if not parts:
        return default_dirs()
    return tuple(Path(p).expanduser().resolve() for p in parts)


def resolve(param: str, path: str, dirs: Sequence[Path]) -> Path:
    """Return ``path`` resolved inside one of ``dirs`` or raise :class:`ParameterError`.

    A relative path is taken relative to each allowed directory in turn (the first
    that holds it wins); the file is not opened here.
    """
    text = str(path)
    if not text.strip():
        raise ParameterError(f'{param}: empty path')
    if '\x00' in text:
        raise ParameterError(f'{param}: the path contains a NUL character')
    p = Path(text).expanduser()
    trials = [p] if p.is_absolute() else [Path(d) / p for d in dirs]
    for trial in trials:
        real = Path(os.path.realpath(trial))
        for d in dirs:
            d = Path(os.path.realpath(d))
            if real == d or d in real.parents:
                return real
    where = ', '.join(str(d) for d in dirs)
    raise ParameterError(f'{param}: {text} is outside the allowed directories ({where}); '
                         'refused without opening it')


def read_text(param: str, path: str, dirs: Sequence[Path], *,
              max_bytes: int = MAX_BYTES) -> tuple[Path, str]:
    """Read a regular UTF-8 file named by a parameter; return ``(resolved path, text)``.

    Raises
    ------
    ParameterError
        Outside ``dirs``, missing, not a regular file (FIFO, device, socket,
        directory), larger than ``max_bytes``, unreadable or not UTF-8 text.  The
        message never contains the file's content.
    """
    real = resolve(param, path, dirs)
    try:
        # O_NONBLOCK: opening a FIFO with no writer would otherwise block the node
        fd = os.open(real, os.O_RDONLY | os.O_NONBLOCK | getattr(os, 'O_CLOEXEC', 0))
    except FileNotFoundError:
        raise ParameterError(f'{param}: {real}: no such file') from None
    except IsADirectoryError:
        raise ParameterError(f'{param}: {real}: is a directory, not a file') from None
    except PermissionError:
        raise ParameterError(f'{param}: {real}: permission denied') from None
    except OSError as exc:
        raise ParameterError(f'{param}: {real}: cannot open ({exc.strerror})') from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            kind = ('a directory' if stat.S_ISDIR(st.st_mode) else
                    'a FIFO' if stat.S_ISFIFO(st.st_mode) else
                    'a device' if stat.S_ISCHR(st.st_mode) or stat.S_ISBLK(st.st_mode) else
                    'a socket' if stat.S_ISSOCK(st.st_mode) else 'not a regular file')
            raise ParameterError(f'{param}: {real}: is {kind}; only regular files are read')
        if st.st_size > max_bytes:
            raise ParameterError(f'{param}: {real}: {st.st_size} bytes, more than the '
                                 f'{max_bytes}-byte bound')
        chunks = []
        total = 0
        while True:
            b = os.read(fd, 1 << 16)
            if not b:
                break
            total += len(b)
            if total > max_bytes:       # grew while being read
                raise ParameterError(f'{param}: {real}: more than the {max_bytes}-byte '
                                     'bound')
            chunks.append(b)
    except BlockingIOError:
        raise ParameterError(f'{param}: {real}: would block; only regular files are '
                             'read') from None
    except OSError as exc:
        raise ParameterError(f'{param}: {real}: cannot read ({exc.strerror})') from None
    finally:
        os.close(fd)
    try:
        return real, b''.join(chunks).decode('utf-8')
    except UnicodeDecodeError:
        raise ParameterError(f'{param}: {real}: not UTF-8 text') from None


def parse_untrusted(param: str, real: Path, text: str, parser: Callable[[str], T], *,
                    what: str) -> T:
    """Parse ``text`` with ``parser``; on failure a reason without the file's content.

    A parser's message may quote the offending line or key (a YAML loader shown
    ``/etc/shadow`` quotes its first line), so the reason keeps only the kind of
    problem: the error's class and, for a syntax error, its line number.
    """
    try:
        return parser(text)
    except Exception as exc:    # any parser failure becomes one content-free line
        line = getattr(getattr(exc, 'problem_mark', None), 'line', None)
        where = f' (syntax error on line {line + 1})' if isinstance(line, int) else ''
        raise ParameterError(f'{param}: {real}: not a valid {what}{where}') from None


__all__ = ['MAX_BYTES', 'default_dirs', 'package_config_dir', 'parse_dirs',
           'parse_untrusted', 'read_text', 'resolve']
