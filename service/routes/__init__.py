"""HTTP routes: thin — validate, call the store, hand job ids to the runner."""
