"""Model files as SB3's ``load`` reads them, checked before it does (:func:`check_loadable`, called by
:class:`~.checks.InputChecksMixin`'s ``load``) and read for single values (:func:`stored_values`).

``load`` refuses, with an error naming the problem, a missing file (naming the paths tried, where SB3 names
``model.zip.zip``), a truncated or corrupted model zip (SB3 itself only asserts "No data found") and a zip that another
algorithm saved (e.g. a TD3 zip given to ``DENFAC.load``, which SB3 would let fail somewhere inside ``_setup_model``).
"""

from __future__ import annotations

import contextlib
import json
import pathlib
import zipfile
from collections.abc import Iterator
from typing import Any

from stable_baselines3.common.save_util import json_to_data


def _open_for_read(path: Any) -> Any:
    """``path`` as SB3's ``load`` resolves it (a missing ``.zip`` suffix is added), or the file object itself."""
    if isinstance(path, (str, pathlib.Path)):
        path = pathlib.Path(path)
        if not path.exists():  # as SB3's open_path: "model" -> "model.zip"
            path = pathlib.Path(f"{path}.zip")
    return path


@contextlib.contextmanager
def _model_zip(path: Any) -> Iterator[zipfile.ZipFile | None]:
    """The model zip at ``path`` as SB3's ``load`` finds it (None if there is no such file), open for reading; a file
    object is read from where it stands and put back there."""
    target = _open_for_read(path)
    if isinstance(target, pathlib.Path) and not target.exists():
        yield None
        return
    position = target.tell() if hasattr(target, "tell") else None
    try:
        with zipfile.ZipFile(target) as archive:
            yield archive
    finally:
        if position is not None:
            target.seek(position)


def _deserialised(data_json: str, keys: tuple[str, ...]) -> dict[str, Any]:
    """Those of ``keys`` the ``data`` entry holds, deserialised as SB3 does (SB3's load deserialises the rest, with its
    own warnings); {} if they cannot be (SB3's own error then tells)."""
    try:
        stored = json.loads(data_json)
        return json_to_data(json.dumps({key: stored[key] for key in keys if key in stored}))
    except Exception:  # noqa: BLE001 - an undecodable value is left to SB3's own error
        return {}


def check_model_zip(path: Any) -> Any:
    """Check that ``path`` is a complete SB3 model zip and return the ``policy_class`` it stores (None if unreadable).

    :raises ValueError: the file is not a zip, lacks the ``data`` entry or has a corrupted entry (bad CRC). A truncated
        model zip is a case of the second: ``zipfile`` then finds the zip of the torch ``.pth`` entry inside it, and
        SB3's own ``load`` only asserts "No data found in the saved file".
    """
    try:
        with _model_zip(path) as archive:
            if archive is None:
                return None  # SB3's load reports the missing file
            if "data" not in archive.namelist():
                raise ValueError(
                    f"{path} is not a complete SB3 model zip (no 'data' entry): the file is truncated or corrupted, "
                    "or was not written by save()"
                )
            bad_entry = archive.testzip()
            if bad_entry is not None:
                raise ValueError(f"{path} is a corrupted model zip (bad CRC in entry {bad_entry!r})")
            data_json = archive.read("data").decode()
    except zipfile.BadZipFile as error:
        raise ValueError(f"{path} is not a zip file: not an SB3 model, or a truncated or corrupted one") from error
    return _deserialised(data_json, ("policy_class",)).get("policy_class")


def stored_values(path: Any, *keys: str) -> dict[str, Any]:
    """The values a model zip stores under ``keys`` in its ``data`` entry, deserialised as SB3 does, read once; a key
    the file lacks, or a file that cannot be read, is left out (SB3's own ``load`` then reports the problem)."""
    try:
        with _model_zip(path) as archive:
            data_json = None if archive is None else archive.read("data").decode()
    except Exception:  # noqa: BLE001 - an unreadable file is left to SB3's own error
        return {}
    return {} if data_json is None else _deserialised(data_json, keys)


def check_model_file_exists(algorithm: str, path: Any) -> None:
    """Raise a ``FileNotFoundError`` naming the file(s) tried if ``path`` (a str or Path) is neither a file nor, with
    ``.zip`` added, one (SB3's own error names ``<path>.zip`` only, e.g. ``model.zip.zip``)."""
    if not isinstance(path, (str, pathlib.Path)):
        return
    given = pathlib.Path(path)
    if given.exists() or pathlib.Path(f"{given}.zip").exists():
        return
    tried = [str(given)] if given.suffix == ".zip" else [str(given), f"{given}.zip"]
    raise FileNotFoundError(
        f"{algorithm}.load: no model file {' or '.join(repr(t) for t in tried)} (looked in {given.resolve().parent})"
    )


def check_loadable(algorithm: type, path: Any, custom_objects: dict[str, Any] | None) -> None:
    """Refuse, with an error naming the problem, a ``path`` that ``algorithm.load`` cannot read: a missing file, one
    that is not a complete SB3 model zip (:func:`check_model_zip`), or one whose policy class is none of the
    algorithm's ``policy_aliases`` (a zip saved by another algorithm; ``custom_objects`` may replace the class)."""
    name = algorithm.__name__
    check_model_file_exists(name, path)
    policy_class = check_model_zip(path)
    policy_class = (custom_objects or {}).get("policy_class", policy_class)
    allowed = tuple(getattr(algorithm, "policy_aliases", {}).values())
    if allowed and isinstance(policy_class, type) and not issubclass(policy_class, allowed):
        raise ValueError(
            f"{name}.load: this model was saved by another algorithm (its policy is "
            f"{policy_class.__module__}.{policy_class.__qualname__}, {name} expects a subclass of "
            f"{', '.join(c.__name__ for c in allowed)}); load it with the class that saved it"
        )
