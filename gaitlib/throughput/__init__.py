"""Speed measurements (``gaitlib throughput``): ratios against a reference measured in the same run."""
