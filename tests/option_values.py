"""A check shared by the tests of the techniques' frozen option values."""

import pytest


def assert_refused_with_one_line(cls, name, bad, exc, words):
    """``cls(name=bad)`` and ``cls().replace(name=bad)`` raise ``exc`` with one line starting
    with ``words`` (the field's qualified name first)."""
    with pytest.raises(exc) as info:
        cls(**{name: bad})
    message = str(info.value)
    assert message.startswith(words), message
    assert "\n" not in message
    # replace() validates like a new value
    with pytest.raises(exc, match="^" + words.split(" ")[0].replace(".", r"\.")):
        cls().replace(**{name: bad})
