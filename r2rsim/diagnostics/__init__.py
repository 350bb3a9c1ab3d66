"""Later pipeline stage (diagnostics): arrives with its issue."""
