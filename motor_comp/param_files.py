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
  keeps only what cannot come from the file — the syntax error's line number, the
  schema's own field names and a fixed phrase for the problem).

Files a parameter makes a node *write* (the recorder's ``output``) follow one rule: the
file is created exclusively (``O_CREAT | O_EXCL``: an existing file or a symbolic link
at the path is refused) in an existing directory, so an output path cannot clobber
anything (:class:`motor_comp.logs.McapRecorder` with ``exclusive=True``).

Core module: no rclpy; the nodes call it from their parameter callbacks.
"""
from __future__ import annotations

import dataclasses
import os
import re
import stat
from pathlib import Path
from typing import Any, Callable, Collection, Sequence, TypeVar

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


def _inside(real: Path, dirs: Sequence[Path]) -> bool:
    for d in dirs:
        d = Path(os.path.realpath(d))
        if real == d or d in real.parents:
            return True
    return False


def resolve(param: str, path: str, dirs: Sequence[Path]) -> Path:
    """Return ``path`` resolved inside one of ``dirs`` or raise :class:`ParameterError`.

    Symbolic links are followed (``realpath``: ``lstat``/``readlink``, never ``open``),
    so a link inside an allowed directory that points outside is outside.  A relative
    path is taken relative to each allowed directory in turn: the first that holds it
    wins, else the first candidate inside (whose read then says there is no such
    file).  The file is not opened here.
    """
    text = str(path)
    if not text.strip():
        raise ParameterError(f'{param}: empty path')
    if '\x00' in text:
        raise ParameterError(f'{param}: the path contains a NUL character')
    p = Path(text).expanduser()
    trials = [p] if p.is_absolute() else [Path(d) / p for d in dirs]
    first: Path | None = None
    for trial in trials:
        real = Path(os.path.realpath(trial))
        if not _inside(real, dirs):
            continue
        if os.path.lexists(real):
            return real
        first = first or real
    if first is not None:
        return first
    where = ', '.join(str(d) for d in dirs)
    raise ParameterError(f'{param}: {text} is outside the allowed directories ({where}); '
                         'refused without opening it')


def _kind(mode: int) -> str:
    """Name the kind of a non-regular file from its ``st_mode``."""
    return ('a directory' if stat.S_ISDIR(mode) else
            'a FIFO' if stat.S_ISFIFO(mode) else
            'a device' if stat.S_ISCHR(mode) or stat.S_ISBLK(mode) else
            'a socket' if stat.S_ISSOCK(mode) else 'not a regular file')


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
        # refused before open(): opening a device can act (a serial line raises DTR, a
        # tape rewinds); the fstat below catches a file swapped in after this check
        st = os.stat(real)
    except FileNotFoundError:
        raise ParameterError(f'{param}: {real}: no such file') from None
    except OSError as exc:
        raise ParameterError(f'{param}: {real}: cannot open ({exc.strerror})') from None
    if not stat.S_ISREG(st.st_mode):
        raise ParameterError(f'{param}: {real}: is {_kind(st.st_mode)}; only regular '
                             'files are read')
    try:
        # O_NONBLOCK: opening a FIFO with no writer would otherwise block the node;
        # O_NOFOLLOW: the resolved path's last component must not have become a link
        fd = os.open(real, os.O_RDONLY | os.O_NONBLOCK | os.O_NOFOLLOW
                     | getattr(os, 'O_CLOEXEC', 0))
    except FileNotFoundError:
        raise ParameterError(f'{param}: {real}: no such file') from None
    except IsADirectoryError:
        raise ParameterError(f'{param}: {real}: is a directory, not a file') from None
    except PermissionError:
        raise ParameterError(f'{param}: {real}: permission denied') from None
    except OSError as exc:   # ELOOP: replaced by a symbolic link since it was resolved
        raise ParameterError(f'{param}: {real}: cannot open ({exc.strerror})') from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise ParameterError(f'{param}: {real}: is {_kind(st.st_mode)}; only regular '
                                 'files are read')
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


#: the problems a parser's message may be reduced to (fixed phrases of the project's own
#: loaders, never text of the file), most specific first
PROBLEMS = ('unknown field', 'unknown effect', 'unknown parameter', 'missing field',
            'missing parameter', 'must be a number', 'must be finite', 'must be >= 0',
            'must be > 0', 'must be one of', 'must be a mapping', 'expected a mapping',
            'expected columns', 'does not have 3 columns', 'non-numeric value',
            'non-finite value', 'strictly increasing', 'at least 2 rows',
            'more than one period', 'is not a number', 'only valid on a rotary axis',
            'empty')

_QUOTED = re.compile(r"'[^'\n]*'|\"[^\"\n]*\"")
_NAME = re.compile(r'[A-Za-z_][A-Za-z0-9_]*(?:\.[A-Za-z_][A-Za-z0-9_]*)*')
_ROW = re.compile(r'\brow (\d+)\b')
_PAREN = re.compile(r'\([^()]*\)')


def _detail(message: str, real: Path, vocabulary: Collection[str]) -> list[str]:
    """Keep of a parser's message what may be shown: schema names, a phrase, a row.

    Quoted text (a parser quotes what it found: an unknown key, a bad value), the path
    and parenthesised lists of the valid names are dropped first; of the rest only a
    dotted name whose every part is in ``vocabulary`` (the schema's field names), the
    first phrase of :data:`PROBLEMS` and a row number survive.
    """
    text = _QUOTED.sub(' ', message.replace(str(real), ' '))
    # a parenthesis lists the valid names ("known: …", "expected […]"), not the culprit
    text = _PAREN.sub(' ', text)
    out = []
    for m in _NAME.finditer(text):
        if all(part in vocabulary for part in m.group().split('.')):
            out.append(m.group())
            break
    problem = next((p for p in PROBLEMS if p in text), None)
    if problem is not None:
        out.append(problem)
    row = _ROW.search(text)
    if row is not None:
        out.append(f'row {int(row.group(1))}')
    return out


def parse_untrusted(param: str, real: Path, text: str, parser: Callable[[str], T], *,
                    what: str, vocabulary: Collection[str] = ()) -> T:
    """Parse ``text`` with ``parser``; on failure a reason without the file's content.

    A parser's message may quote the offending line or key (a YAML loader shown
    ``/etc/shadow`` quotes its first line), so the reason keeps only what cannot come
    from the file: the line number of a syntax error, the first name of the message
    made of ``vocabulary`` words (the schema's own field names, e.g. ``coulomb.fc``),
    a fixed phrase of :data:`PROBLEMS` and a row number.

    Parameters
    ----------
    param : str
        Parameter name (first word of the reason).
    real : Path
        The resolved file (named in the reason).
    text : str
        The file's content, as :func:`read_text` returned it.
    parser : callable
        ``text`` → the parsed object; any exception is a rejection.
    what : str
        What the file should be (``model file``, ``compensation table``).
    vocabulary : collection of str
        Field names of the file's schema that a reason may name.
    """
    try:
        return parser(text)
    except Exception as exc:    # any parser failure becomes one content-free line
        # a YAML error's position, also when a loader wrapped it (``raise … from``)
        mark = next((getattr(e, 'problem_mark', None) for e in (exc, exc.__cause__)
                     if getattr(e, 'problem_mark', None) is not None), None)
        line = getattr(mark, 'line', None)
        parts = [f'syntax error on line {line + 1}'] if isinstance(line, int) else \
            _detail(str(exc), real, vocabulary)
        where = f' ({"; ".join(parts)})' if parts else ''
        raise ParameterError(f'{param}: {real}: not a valid {what}{where}') from None


def load(param: str, path: str, dirs: Sequence[Path], parser: Callable[[str], T], *,
         what: str, vocabulary: Collection[str] = (),
         max_bytes: int = MAX_BYTES) -> tuple[Path, T]:
    """Read (:func:`read_text`) and parse (:func:`parse_untrusted`) a parameter's file.

    Returns ``(resolved path, parsed object)``; every failure is a
    :class:`ParameterError` whose message never contains the file's content.
    """
    real, text = read_text(param, path, dirs, max_bytes=max_bytes)
    return real, parse_untrusted(param, real, text, parser, what=what,
                                 vocabulary=vocabulary)


# ---- the files node parameters name ---------------------------------------------------
def model_vocabulary() -> frozenset[str]:
    """Return the field names of a model file: top level, effects, effect parameters."""
    from motor_comp.physics.axis import MODEL_FIELDS
    from motor_comp.physics.effects import EFFECTS
    names = set(MODEL_FIELDS) | set(EFFECTS)
    for cls in EFFECTS.values():
        names.update(f.name for f in dataclasses.fields(cls))
    return frozenset(names)


#: what the loaders below call the file in their messages: not a schema word, so that
#: :func:`parse_untrusted` never takes it for a field (the reason names the path itself)
SOURCE = '<file>'

#: the column and header names of a compensation table (``motor-comp export-table``)
TABLE_VOCABULARY = frozenset({'position', 'force', 'command', 'period', 'input_gain',
                              'effects', 'source_model', 'units'})


def load_model(param: str, path: str, dirs: Sequence[Path]) -> tuple[Path, Any]:
    """Read and parse the model file (DESIGN.md §6) a parameter names.

    Returns ``(resolved path, AxisModel)``; a :class:`ParameterError` without the
    file's content otherwise.
    """
    from motor_comp.physics.axis import AxisModel
    return load(param, path, dirs, lambda text: AxisModel.from_text(text, source=SOURCE),
                what='model file', vocabulary=model_vocabulary())


def load_table(param: str, path: str, dirs: Sequence[Path]) -> tuple[Path, Any]:
    """Read and parse the compensation table CSV a parameter names.

    Returns ``(resolved path, PositionTable)``; a :class:`ParameterError` without the
    file's content otherwise.
    """
    from motor_comp.control.compensation import table_from_text
    return load(param, path, dirs, lambda text: table_from_text(text, source=SOURCE),
                what='compensation table', vocabulary=TABLE_VOCABULARY)


def load_plant(param: str, name: str, dirs: Sequence[Path]) -> Any:
    """Return the plant a parameter names: ``pmlm``, ``ballscrew`` or a plant YAML file.

    The packaged plants are not files a parameter names (no directory rule); a path is
    read under the rules above.  Returns a :class:`~motor_comp.physics.config.PlantConfig`.
    """
    from motor_comp.physics.config import PlantKind, packaged_plant, plant_from_text, \
        plant_names
    if name in {k.value for k in PlantKind}:
        return packaged_plant(name)
    vocabulary = frozenset(plant_names()) | model_vocabulary()
    real, cfg = load(param, name, dirs, lambda text: plant_from_text(text, source=SOURCE),
                     what='plant file', vocabulary=vocabulary)
    return dataclasses.replace(cfg, source=str(real))


__all__ = ['MAX_BYTES', 'PROBLEMS', 'SOURCE', 'TABLE_VOCABULARY', 'default_dirs', 'load',
           'load_model', 'load_plant', 'load_table', 'model_vocabulary',
           'package_config_dir', 'parse_dirs', 'parse_untrusted', 'read_text', 'resolve']
