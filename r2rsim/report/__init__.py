"""Later pipeline stage (report): arrives with its issue."""
