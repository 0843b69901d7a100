"""Files in and out: trajectory formats, frame conventions, results folder."""
