// placeholder: filled by its stage's work
