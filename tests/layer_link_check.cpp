// The empty program of the layer link checks (CMakeLists.txt, "The target graph holds the
// layers"): linking one library whole with only the layers below it is the test.
int main() { return 0; }
