"""Post-processing: fields sampled from a solution and the measures of the summary."""
