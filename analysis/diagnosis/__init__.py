"""Model-error diagnosis: where the model fails, which physical effect is missing, add it."""
