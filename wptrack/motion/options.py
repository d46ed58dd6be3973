"""Which motion-mask options each mask method uses, so an option given for another method is refused in one line
instead of being silently ignored (``wptrack masks --method mog2 --window 50`` once ran with the window unused).

:class:`~wptrack.motion.masks.MaskConfig` holds the options of every method: the offline background model's
(``window``, ``samples``, the thresholds, the shadow band, the light model ``illum_*`` ...), the online models'
(``history``, ``learning_rate``; ``var_threshold`` for MOG2, ``dist2_threshold`` for KNN), the clean-up of
subtracted masks (``open_px``, ``close_px``, ``min_area``: given masks are only thresholded) and the threshold of
given masks. :func:`methods_using` says which methods read a field; :func:`check_mask_options` is called by
``wptrack masks``, ``wptrack track`` and ``wptrack batch`` manifests with the options the user gave.
"""

from __future__ import annotations

from collections.abc import Iterable

from wptrack.core.config import fields_of, option_map
from wptrack.core.errors import ConfigError
from wptrack.motion.masks import METHODS, MaskConfig

__all__ = ["check_mask_options", "methods_using"]

SUBTRACTED = ("offline", "mog2", "knn")
"""The methods that make masks from camera frames (the others read given masks)."""

_USED_BY: dict[str, tuple[str, ...]] = {
    "method": METHODS,
    "history": ("mog2", "knn"),
    "var_threshold": ("mog2",),
    "dist2_threshold": ("knn",),
    "learning_rate": ("mog2", "knn"),
    "detect_shadows": SUBTRACTED,
    "open_px": SUBTRACTED,
    "close_px": SUBTRACTED,
    "min_area": SUBTRACTED,
    "threshold": ("given",),
}
"""The fields not of the offline model alone (those say "offline:" first in their help) and not of every method."""


def methods_using(field: str) -> tuple[str, ...]:
    """The mask methods that read MaskConfig ``field``: listed in ``_USED_BY``, else the offline model's when its
    help starts with ``offline:``, else every method."""
    if field in _USED_BY:
        return _USED_BY[field]
    for f, p, _ in fields_of(MaskConfig):
        if f.name == field:
            return ("offline",) if p is not None and p.help.startswith("offline:") else METHODS
    raise KeyError(field)


def _whose(methods: tuple[str, ...], method_flag: str) -> str:
    if methods == ("offline",):
        return f"of the offline background model ({method_flag} offline)"
    if methods == SUBTRACTED:
        return "of masks made from camera frames (offline, mog2, knn; given masks are only thresholded)"
    if methods == ("given",):
        return "of given masks (--masks) only"
    return f"of {method_flag} {' and '.join(methods)} only"


def check_mask_options(
    config: MaskConfig, flags: Iterable[str], prefix: str = "", dashes: str = "--", given_masks: bool = False
) -> None:
    """Refuse MaskConfig options given for a method that does not use them.

    Args:
        config: The masks' config (its ``method``).
        flags: The options given (flags of :func:`wptrack.core.config.option_map` with ``prefix``, without dashes).
        prefix: The options' prefix (``mask-`` for ``wptrack track``).
        dashes: Put before a flag in the message (``--`` on the command line, ``""`` in a manifest).
        given_masks: The run reads given masks (``--masks``): the method is ``given`` whatever ``method`` says.

    Raises:
        ConfigError: the first such option, what uses it and that it would have no effect.
    """
    options = option_map(MaskConfig, prefix)
    method = "given" if given_masks else config.method
    method_flag = f"{dashes}{prefix}method"
    context = f"on given masks ({dashes}masks)" if given_masks else f"with {method_flag} {method}"
    for flag in flags:
        opt = options.get(flag)
        if opt is None:
            continue
        field = opt.path[-1]
        if field == "method":
            if given_masks and config.method != "given":
                raise ConfigError(
                    f"{method_flag} {config.method}: given masks ({dashes}masks) are read, not made; it has no effect: "
                    f"leave it out (or give {dashes}video instead of {dashes}masks)"
                )
            continue
        users = methods_using(field)
        if method not in users:
            name = f"{dashes}{flag}"
            if opt.param is not None and opt.param.negative:  # a boolean of two flags: --detect-shadows/--keep-shadows
                name += f"/{dashes}{prefix}{opt.param.negative}"
            raise ConfigError(
                f"{name}: an option {_whose(users, method_flag)}; it has no effect {context}: leave it out"
            )
