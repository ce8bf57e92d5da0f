// feature_map: being written (issue 6).
