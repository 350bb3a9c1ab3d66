"""Later pipeline stage (evaluate): arrives with its issue."""
