"""vascsim dashboard package."""
