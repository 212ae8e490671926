"""Tools over datasets: statistics (``brdfgan dataset-stats``), contact sheets
and the Deschaintre et al. 2018 dataset converter."""
