"""vascsim sessions package."""
