"""vascsim recorder package."""
