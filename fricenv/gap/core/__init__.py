"""What every plant's gap diagnosis shares: noise levels, the verdict rule, the report files, the parallel map."""
