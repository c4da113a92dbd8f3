"""Data in and out: datasets, your own joint clips, BVH files, pictures and animations."""
