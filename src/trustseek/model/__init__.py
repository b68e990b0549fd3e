"""The supervisor and the task: ``TrustModel`` (trust dynamics and human actions; ``IOHMMModel``
is the same model with any named inputs), ``Task``
(complexities, success probabilities, rewards of eq. (1), discount), their JSON formats, and
the built-in presets.

Each name is loaded on first use (the names are in ``__init__.pyi``).
"""

import lazy_loader as _lazy

__getattr__, __dir__, __all__ = _lazy.attach_stub(__name__, __file__)
