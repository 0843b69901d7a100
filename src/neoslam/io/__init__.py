"""Files in and out: trajectory formats, tables, the results folder, outputs written whole, input checks."""
