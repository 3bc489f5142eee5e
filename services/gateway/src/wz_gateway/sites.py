"""The sites one gateway serves: its own on a trailer, every trailer's at the centre.

A trailer's gateway serves one site, the one in ``WZ_SITE_FILE``. A central gateway, connected
to the regional router, is given every trailer's site file (``WZ_GATEWAY_SITE_FILES``, files
or folders of ``*.yaml``): it subscribes to ``wz/*/...`` and stores what each site publishes,
placed with that site's geometry. The first site is the API's default ``site``.

A message of a site the gateway was not given is counted (``unknown_site``) and dropped: the
gateway cannot place a track without the site's geometry, and an unexpected site on the bus
is something for an operator to look at (a new trailer whose file the centre lacks, or a
misconfigured one).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path

from wz_shared.keys import Keys
from wz_shared.site import Site, SiteFileError, load_site


class Sites:
    """An ordered, non-empty set of sites, by site id; the first is the default."""

    def __init__(self, sites: Iterable[Site]) -> None:
        self._by_id: dict[str, Site] = {}
        for site in sites:
            if site.site_id in self._by_id:
                raise SiteFileError(f"site {site.site_id} is given twice")
            self._by_id[site.site_id] = site
        if not self._by_id:
            raise SiteFileError("no site to serve")

    @classmethod
    def of(cls, site: Site | Sites) -> Sites:
        return site if isinstance(site, Sites) else cls([site])

    @property
    def default(self) -> Site:
        return next(iter(self._by_id.values()))

    @property
    def ids(self) -> list[str]:
        return list(self._by_id)

    @property
    def several(self) -> bool:
        return len(self._by_id) > 1

    def get(self, site_id: str) -> Site | None:
        return self._by_id.get(site_id)

    def __contains__(self, site_id: object) -> bool:
        return site_id in self._by_id

    def __iter__(self) -> Iterator[Site]:
        return iter(self._by_id.values())

    def __len__(self) -> int:
        return len(self._by_id)

    def key(self, suffix: str) -> str:
        """The key expression of ``suffix`` (``tracks``, ``alerts/*`` ...) over these sites:
        the site's own key for one site, ``wz/*/<suffix>`` for several."""
        if self.several:
            return Keys.all_sites(suffix)
        return f"{Keys(self.default.site_id).prefix}/{suffix}"


def site_file_paths(entries: Sequence[Path]) -> list[Path]:
    """Site files from files and folders (a folder: its ``*.yaml`` and ``*.yml``, sorted)."""
    paths: list[Path] = []
    for entry in entries:
        if entry.is_dir():
            found = sorted([*entry.glob("*.yaml"), *entry.glob("*.yml")])
            if not found:
                raise SiteFileError(f"no site file (*.yaml) in folder {entry}")
            paths += found
        else:
            paths.append(entry)
    return paths


def load_sites(entries: Sequence[Path]) -> Sites:
    """Read every site file of ``entries`` (files or folders); :class:`SiteFileError` names
    the file that is missing or wrong, or a site id given twice."""
    return Sites(load_site(path) for path in site_file_paths(entries))
