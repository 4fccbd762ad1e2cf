"""Readers and writers of data formats; every reader returns insgnss-convention DataFrames."""
