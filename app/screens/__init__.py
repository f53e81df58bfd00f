"""Full screens pushed over the tabs: the arm's view (``arm``)."""
