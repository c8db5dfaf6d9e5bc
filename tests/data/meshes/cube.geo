// Unit cube [0,1]^3, coarse tetrahedral mesh.
SetFactory("Built-in");
lc = 0.6;
Point(1) = {0, 0, 0, lc};
Extrude {1, 0, 0} { Point{1}; }
Extrude {0, 1, 0} { Line{1}; }
Extrude {0, 0, 1} { Surface{5}; }
