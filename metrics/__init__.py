"""vascsim metrics package."""
