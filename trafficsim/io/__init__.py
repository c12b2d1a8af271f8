"""File input and output: YAML loading with located errors, scenario and spec schemas."""
