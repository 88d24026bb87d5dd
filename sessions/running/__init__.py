"""Running sessions with a person at the station: the live window, its heads-up strip, the scene it
shows, and the station's flow from instructions through a trial to its feedback."""
