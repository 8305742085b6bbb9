"""One small registry: name -> object, for backbones, heads, IIL algorithms and environments.

Pure Python (no torch), so a torch-free module can hold one and list its names. Duplicates
raise; an unknown name raises one line that lists the valid ones
(``Unknown backbone: 'vgg'; valid: mobilenet_v2, ...``). With a ``catalogue`` (the one ordered
list of names that may exist, e.g. :data:`crossing_assist.iil.config.ALGORITHMS`) only those
names register, and :meth:`Registry.names` follows its order; otherwise registration order.
"""

from __future__ import annotations

from typing import Callable, Generic, Iterator, Sequence, TypeVar

T = TypeVar("T")


class Registry(Generic[T]):
    """``kind`` names the things in error messages; ``error`` is the exception class raised
    (a ``ValueError`` subclass, e.g. ``BackboneError``)."""

    def __init__(self, kind: str, *, error: type[Exception] = ValueError,
                 catalogue: Sequence[str] | None = None, catalogue_name: str = "the catalogue") -> None:
        self.kind = kind
        self.error = error
        self.catalogue = None if catalogue is None else tuple(catalogue)
        self.catalogue_name = catalogue_name
        self._items: dict[str, T] = {}

    def register(self, name: str, obj: T | None = None) -> T | Callable[[T], T]:
        """``register(name, obj)`` adds ``obj``; ``@register(name)`` decorates. Raises ``error``
        for a name already registered or, with a catalogue, a name not in it."""
        if self.catalogue is not None and name not in self.catalogue:
            raise self.error(f"Unknown {self.kind}: {name!r}; list it in {self.catalogue_name} first")

        def add(item: T) -> T:
            if name in self._items:
                raise self.error(f"{self.kind.capitalize()} {name!r} is already registered")
            self._items[name] = item
            return item
        return add if obj is None else add(obj)

    def get(self, name: str) -> T:
        """The object registered as ``name``; raises ``error`` listing the valid names."""
        try:
            return self._items[name]
        except (KeyError, TypeError):
            raise self.error(f"Unknown {self.kind}: {name!r}; valid: {', '.join(self.names())}") from None

    def names(self) -> tuple[str, ...]:
        """The registered names: the catalogue's order if there is one, else registration order."""
        if self.catalogue is None:
            return tuple(self._items)
        return tuple(n for n in self.catalogue if n in self._items)

    def __contains__(self, name: object) -> bool:
        return name in self._items

    def __iter__(self) -> Iterator[str]:
        return iter(self.names())

    def __len__(self) -> int:
        return len(self._items)
