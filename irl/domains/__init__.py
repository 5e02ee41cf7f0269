"""The paper's benchmark domains: Forestworld and onion sorting."""

from irl.domains.base import Domain
from irl.domains.forestworld import forestworld
from irl.domains.onion_sorting import onion_sorting

__all__ = ["Domain", "forestworld", "onion_sorting"]
