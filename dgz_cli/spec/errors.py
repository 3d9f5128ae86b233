"""One exception family (kept in `spec` so every layer can raise it without importing upward).

The CLI turns a :class:`DgzError` into one red line plus the hint and exit code 1; anything else is a bug.
"""

from __future__ import annotations


class DgzError(Exception):
    """Base class: ``message`` names the file/field/port, ``hint`` says what to do about it."""

    def __init__(self, message: str, hint: str = "") -> None:
        super().__init__(message)
        self.message = message
        self.hint = hint

    def __str__(self) -> str:
        return f"{self.message} ({self.hint})" if self.hint else self.message


class UrdfError(DgzError):
    """A URDF/xacro file (or a mesh it references) cannot be used."""


class SpecError(DgzError):
    """A HandSpec file is missing, malformed or inconsistent."""


class OnboardError(DgzError):
    """Onboarding could not decide something and needs the user's help."""


class AssetError(DgzError):
    """An asset root or an asset under it cannot be found."""
