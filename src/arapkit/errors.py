"""Exception raised for bad user input, and messages worded for the interface that shows them.

Every message is one line that names the file, vertex, handle or group at fault,
so the command line can print it as is and exit with status 2. A message that tells the
user to change an option is an :class:`Advice`: Python code reads ``weights='cotan'``,
the command line ``--weights cotan`` and the editor its Solver panel.
:func:`require_extra` is the one door check for the optional extras (figures, editor ...).
"""

from __future__ import annotations

import importlib
from collections.abc import Sequence
from types import ModuleType


class InputError(ValueError):
    """A user-supplied mesh, handle set, rigidity map or option is invalid.

    Examples
    --------
    >>> raise InputError("bar.off: face 3 references vertex 99 (mesh has 10)")
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: bar.off: face 3 references vertex 99 (mesh has 10)
    """


#: the interfaces a message can be worded for
INTERFACES = ("python", "cli", "editor", "blender")


#: the editor's controls for options that are not in its Solver panel
EDITOR_CONTROLS = {"rings": "Global r {value} in the Rigidity panel"}


def option(name: str, value: str | int, interface: str = "python") -> str:
    """How a user sets option ``name`` to ``value`` in the given interface.

    Examples
    --------
    >>> option("weights", "cotan-clamped"), option("weights", "cotan-clamped", "cli")
    ("weights='cotan-clamped'", '--weights cotan-clamped')
    >>> option("weights", "cotan-clamped", "editor")
    "weights 'cotan-clamped' in the Solver panel"
    >>> option("weights", "cotan-clamped", "blender")
    "Weights 'cotan-clamped' in the ARAP Deform panel"
    >>> option("rings", 4), option("rings", 4, "cli"), option("rings", 4, "editor")
    ('rings=4', '--rings 4', 'Global r 4 in the Rigidity panel')
    """
    if interface == "cli":
        return f"--{name.replace('_', '-')} {value}"
    if interface == "editor":
        control = EDITOR_CONTROLS.get(name)
        return (control.format(value=value) if control
                else f"{name} '{value}' in the Solver panel")
    if interface == "blender":
        return f"{name.replace('_', ' ').capitalize()} '{value}' in the ARAP Deform panel"
    return f"{name}={value!r}"


class Advice(str):
    """A message that names an option, worded for Python until asked otherwise.

    The library raises and records messages in Python's words (``weights='cotan'``); the
    command line and the editor show the same message with their own control
    (``--weights cotan``, the Solver panel) through :func:`worded_for`.

    Examples
    --------
    >>> a = Advice("the shape drifts; use {weights}", weights="cotan-clamped")
    >>> str(a)
    "the shape drifts; use weights='cotan-clamped'"
    >>> a.worded_for("cli")
    'the shape drifts; use --weights cotan-clamped'
    """

    def __new__(cls, template: str, **options: str | int) -> Advice:
        self = super().__new__(cls, cls._fill(template, options, "python"))
        self._template = template
        self._options = options
        return self

    @staticmethod
    def _fill(template: str, options: dict[str, str | int], interface: str) -> str:
        return template.format(**{k: option(k, v, interface) for k, v in options.items()})

    def worded_for(self, interface: str) -> str:
        """The message with each option named as ``interface`` sets it."""
        return self._fill(self._template, self._options, interface)

    def after(self, prefix: str) -> Advice:
        """This advice with plain text in front (the text is kept verbatim).

        Examples
        --------
        >>> Advice("use {weights}", weights="uniform").after("x.off: ").worded_for("cli")
        'x.off: use --weights uniform'
        """
        escaped = prefix.replace("{", "{{").replace("}", "}}")
        return Advice(escaped + self._template, **self._options)

    def before(self, suffix: str) -> Advice:
        """This advice with plain text after it (the text is kept verbatim).

        Examples
        --------
        >>> Advice("use {weights}", weights="uniform").before(" here").worded_for("cli")
        'use --weights uniform here'
        """
        escaped = suffix.replace("{", "{{").replace("}", "}}")
        return Advice(self._template + escaped, **self._options)


def worded_for(message: object, interface: str) -> str:
    """``message`` worded for ``interface`` when it is :class:`Advice`, else ``str(message)``.

    Examples
    --------
    >>> worded_for(InputError(Advice("use {weights}", weights="uniform")).args[0], "cli")
    'use --weights uniform'
    >>> worded_for("plain text", "cli")
    'plain text'
    """
    return message.worded_for(interface) if isinstance(message, Advice) else str(message)


class MissingExtraError(InputError, ImportError):
    """An optional extra that a command or module needs is not installed.

    An :class:`InputError`, so the command line prints its one line and exits with 2, and an
    :class:`ImportError`, so code that guards an optional import catches it as usual.

    Examples
    --------
    >>> isinstance(MissingExtraError("x"), (InputError, ImportError))
    True
    """


def require_extra(modules: str | Sequence[str], extra: str, what: str) -> list[ModuleType]:
    """Import ``modules``, or say in one line which extra of arapkit provides them.

    Parameters
    ----------
    modules : name or names of the modules the extra installs (e.g. ``"viser"``).
    extra : the extra's name in ``pip install 'arapkit[extra]'``.
    what : the command or module that needs it, as the user called it.

    Returns
    -------
    The imported modules, in order.

    Raises
    ------
    MissingExtraError
        ``"<what> needs the <extra> extra: pip install 'arapkit[<extra>]'"``.

    Examples
    --------
    >>> [m.__name__ for m in require_extra("json", "editor", "arapkit edit")]
    ['json']
    >>> require_extra("no_such_module_here", "plots", "--figure")
    Traceback (most recent call last):
    ...
    arapkit.errors.MissingExtraError: --figure needs the plots extra: pip install 'arapkit[plots]'
    """
    names = [modules] if isinstance(modules, str) else list(modules)
    try:
        return [importlib.import_module(name) for name in names]
    except ImportError as e:
        # only the module itself missing is the extra's absence; a broken install's own
        # ImportError (a missing shared library ...) is another problem and is shown as is
        if e.name is None or e.name.split(".")[0] not in {n.split(".")[0] for n in names}:
            raise
        raise MissingExtraError(
            f"{what} needs the {extra} extra: pip install 'arapkit[{extra}]'"
        ) from e
