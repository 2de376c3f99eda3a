"""Dropping a replaced structure and engine without holding the loop.

Freeing a large structure's arrays returns their pages to the kernel one `munmap` at a
time, with the GIL held throughout: on the loop thread, or in one go on any other, that
is a pose gap (`sasprobe bench daemon` measures the gaps under a loading client). So the
loop only hands what it replaced to `DeferredRelease`, and the control thread, once the
change is applied, frees the arrays one at a time with a GIL break between: the loop
waits at most for one array's free.
"""

from __future__ import annotations

import collections
import time

import numpy as np

WALK_DEPTH = 4  # structure/engine -> grid -> its arrays, with room to spare


def arrays_within(objects, depth: int = WALK_DEPTH) -> list[np.ndarray]:
    """The numpy arrays reachable from `objects` through attributes, dicts, lists and
    tuples, down to `depth` levels, each once. Breadth first, so that an object is opened at
    its shallowest level; a loop, not a recursive closure (a closure that calls itself is
    a reference cycle, which would keep the arrays until the next garbage collection)."""
    found: list[np.ndarray] = []
    seen: set[int] = set()
    queue = collections.deque([(objects, 0)])
    while queue:
        obj, level = queue.popleft()
        if id(obj) in seen or level > depth:
            continue
        seen.add(id(obj))
        if isinstance(obj, np.ndarray):
            found.append(obj)
        elif isinstance(obj, dict):
            queue.extend((value, level + 1) for value in obj.values())
        elif isinstance(obj, (list, tuple)):
            queue.extend((value, level + 1) for value in obj)
        elif hasattr(obj, "__dict__") and not isinstance(obj, type):
            queue.append((vars(obj), level))
    return found


class DeferredRelease:
    """What the loop replaced, waiting to be freed off the loop thread."""

    def __init__(self) -> None:
        self._queue: collections.deque = collections.deque()

    def add(self, *objects) -> None:
        """On the loop thread: keep `objects` alive until `release` (a deque append)."""
        self._queue.append(objects)

    def release(self) -> None:
        """Off the loop thread: free what was retired, an array at a time."""
        while self._queue:
            objects = self._queue.popleft()
            arrays = arrays_within(objects)
            del objects  # the objects go now; their arrays live on in `arrays`
            while arrays:
                arrays.pop()  # the last reference, unless someone else still holds it
                time.sleep(0)  # a GIL break: the loop runs between two frees
