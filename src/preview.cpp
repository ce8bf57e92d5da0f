// preview: being written (issue 6).
