"""The three policy networks of the paper (π_h, π_m, π_l), their training and scoring."""
