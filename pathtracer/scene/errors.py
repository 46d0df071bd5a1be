"""The one error type for bad input: it names the file and the JSON path."""


class SceneError(Exception):
    """Bad scene input. ``str()`` is one line: ``file: /json/path: message``."""

    def __init__(self, message, file=None, pointer=None):
        super().__init__(message)
        self.message = message
        self.file = file
        self.pointer = pointer

    def __str__(self):
        parts = [str(p) for p in (self.file, self.pointer) if p]
        return ": ".join(parts + [self.message])
