// Isotropic remeshing of a new patch on plain arrays (work in progress).
