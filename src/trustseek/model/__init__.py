"""The supervisor and the task: ``TrustModel`` (trust dynamics and human actions; the paper's
inputs, ``trust_model``, or any named inputs: a general model), ``Task``
(complexities, success probabilities, rewards of eq. (1), discount), their JSON formats, and
the built-in presets.

Each name is loaded on first use (the names are in ``__init__.pyi``).
"""

import lazy_loader as _lazy

__getattr__, __dir__, __all__ = _lazy.attach_stub(__name__, __file__)
