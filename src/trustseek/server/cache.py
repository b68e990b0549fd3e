"""``Bounded``: the server's one bounded mapping (the least recently used entries forgotten
first), for what it remembers, always in objects the application owns (``app.state``), never in
a module: ``StudyCaches``, the sessions' tokens (``auth.Caller``), the deploy sessions' plans
(``plan.Plans``) with their decisions and belief updates, and their live rows
(``deploy.store.DeployStore``)."""

from __future__ import annotations

from collections import OrderedDict
from typing import Any, Generic, TypeVar

K = TypeVar("K")
V = TypeVar("V")


class Bounded(Generic[K, V]):
    """A mapping of at most ``size`` entries: adding one beyond forgets the least recently used."""

    __slots__ = ("_items", "size")

    def __init__(self, size: int):
        self.size = size
        self._items: OrderedDict[K, V] = OrderedDict()

    def get(self, key: K) -> V | None:
        value = self._items.get(key)
        if value is not None:
            try:  # noqa: SIM105 (a hot path: contextlib.suppress costs several times more)
                self._items.move_to_end(key)
            except KeyError:  # forgotten meanwhile by another thread
                pass
        return value

    def put(self, key: K, value: V) -> V:
        self._items[key] = value
        self._items.move_to_end(key)
        if len(self._items) > self.size:
            self._items.popitem(last=False)
        return value

    def pop(self, key: K) -> None:
        self._items.pop(key, None)

    def clear(self) -> None:
        self._items.clear()

    def __len__(self) -> int:
        return len(self._items)

    def __contains__(self, key: object) -> bool:
        return key in self._items


#: schedule policies are large (megabytes of JSON each): only a few are kept resolved
MAX_CACHED_SCHEDULES = 8


class StudyCaches:
    """What the study sessions remember, owned by the application (``app.state.study_caches``);
    a database session made by the application's ``db`` carries it (``caches_of``).  A study's
    configuration, its stored policies and the policies resolved from specs never change."""

    def __init__(self) -> None:
        self.configs: Bounded[str, dict[str, Any]] = Bounded(256)  # study id -> its configuration
        self.contexts: Bounded[str, Any] = Bounded(256)  # study id -> its blocks' plans (sessions.block_plan)
        self.resolved: Bounded[str, dict[str, Any]] = Bounded(64)  # (model, task, spec) -> policy JSON
        self.schedules: Bounded[str, dict[str, Any]] = Bounded(MAX_CACHED_SCHEDULES)  # the same, schedule policies


def caches_of(db: Any) -> StudyCaches:
    """The application's ``StudyCaches`` that database session ``db`` carries (``info``), or
    empty ones that remember nothing beyond the call (a session made elsewhere)."""
    found = db.info.get("caches")
    return found if isinstance(found, StudyCaches) else StudyCaches()
