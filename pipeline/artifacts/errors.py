"""The artifact store's error: a missing, mistyped, corrupted or busy artifact."""


class ArtifactError(RuntimeError):
    """A missing, incomplete or corrupted artifact; the message says what to do."""
