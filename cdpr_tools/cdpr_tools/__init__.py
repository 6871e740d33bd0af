"""cdpr_tools: the cdpr command, bags, launcher and identification."""
