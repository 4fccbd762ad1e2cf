"""Process models: LLF strapdown (forward and inverse) and RISS."""
