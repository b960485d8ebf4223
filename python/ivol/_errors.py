"""Exceptions of the ivol package: one class per error class of the spec (§13).

Every error libformat raises arrives as an instance of IvolError whose
``error_class`` is the spec's name ("not-ivol", "checksum", ...), and whose
type is the subclass for that name, so callers can catch a damaged file
apart from an unsupported one without parsing messages.
"""


class IvolError(Exception):
    """An error of libformat; ``error_class`` is the spec's name for it."""

    error_class = None

    def __init__(self, message, error_class=None):
        super().__init__(message)
        if error_class is not None:
            self.error_class = error_class


class NotIvolError(IvolError):
    error_class = "not-ivol"


class UnsupportedVersionError(IvolError):
    error_class = "unsupported-version"


class UnsupportedFeatureError(IvolError):
    error_class = "unsupported-feature"


class TruncatedError(IvolError):
    error_class = "truncated"


class ChecksumError(IvolError):
    error_class = "checksum"


class MalformedError(IvolError):
    error_class = "malformed"


class LimitExceededError(IvolError):
    error_class = "limit-exceeded"


class IvolIOError(IvolError):
    error_class = "io"


class InvalidArgumentError(IvolError, ValueError):
    error_class = "invalid-argument"


_BY_NAME = {
    cls.error_class: cls
    for cls in (
        NotIvolError,
        UnsupportedVersionError,
        UnsupportedFeatureError,
        TruncatedError,
        ChecksumError,
        MalformedError,
        LimitExceededError,
        IvolIOError,
        InvalidArgumentError,
    )
}


def error_for(name):
    """The class for the spec's error class `name` (IvolError if unknown)."""
    return _BY_NAME.get(name, IvolError)
