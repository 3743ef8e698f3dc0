"""Figures (matplotlib, object-oriented, no pyplot state): the paper's figures of a sweep,
the leak-rate figures, and the ensemble figures.

Each module draws from results (a sweep table, an ensemble directory) and writes files
atomically; none of them computes physics.
"""

from .flow import flow_figures, flux_magnitude, level_flow, save_flow_figures
from .paper import (
    CLASS_COLOURS,
    CLASS_NAMES,
    default_map_levels,
    figure_class_map,
    figure_topography_moments,
    figure_vpg_moments,
    figure_vpg_volume_gap,
    paper_figures,
    plot_class_map,
    plot_moments,
    plot_topography,
    plot_vpg_vs_free_volume,
    plot_vpg_vs_m0,
    plot_vpg_vs_m2,
    plot_vpg_vs_mean_gap,
    remove_stale_temporaries,
    save_figure,
    save_paper_figures,
)
from .plastic import (
    figure_plastic_area,
    figure_plastic_leak_rate,
    plastic_figures,
    save_plastic_figures,
)

__all__ = [
    "figure_plastic_area",
    "figure_plastic_leak_rate",
    "plastic_figures",
    "save_plastic_figures",
    "CLASS_COLOURS",
    "CLASS_NAMES",
    "default_map_levels",
    "figure_class_map",
    "figure_topography_moments",
    "figure_vpg_moments",
    "figure_vpg_volume_gap",
    "flow_figures",
    "flux_magnitude",
    "level_flow",
    "paper_figures",
    "plot_class_map",
    "plot_moments",
    "plot_topography",
    "plot_vpg_vs_free_volume",
    "plot_vpg_vs_m0",
    "plot_vpg_vs_m2",
    "plot_vpg_vs_mean_gap",
    "remove_stale_temporaries",
    "save_figure",
    "save_flow_figures",
    "save_paper_figures",
]
