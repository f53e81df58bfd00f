"""The app's screens: the tabs' own, drawn by the rows that changed (``live``), and full
screens pushed over the tabs: the arm's view (``arm``)."""
