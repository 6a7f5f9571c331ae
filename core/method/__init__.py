"""The method: observations, reliable region, sampling, reconstruction, KL selection, pipeline."""
