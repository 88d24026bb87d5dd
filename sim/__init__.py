"""vascsim sim package."""
