"""The microbearing REST service and command line: the top of the dependency tree."""
