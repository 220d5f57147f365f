(*

category:      Test
synopsis:      Several parameters with initial assignment rules, testing various L1 built-in functions acting on constants.
componentTags: InitialAssignment, Parameter
testTags:      InitialValueReassigned, UncommonMathML
testType:      TimeCourse
levels:        2.2, 2.3, 2.4, 2.5, 3.1, 3.2
generatedBy:   Analytic

 The model tests the various mathematical constructs present in L1, used in InitialAssignments.

The model contains:
* 40 parameters (P1, P2, P3, P4, P5, P6, P7, P8, P9, P10, P11, P12, P13, P14, P15, P16, P17, P18, P19, P20, P21, P22, P23, P24, P25, P26, P27, P28, P29, P30, P31, P32, P33, P34, P35, P36, P37, P38, P39, P40)
The initial conditions are as follows:

[{width:35em,margin: 1em auto}|       | *Value* | *Constant* |
| Initial value of parameter P1 | $3.7$ | constant |
| Initial value of parameter P2 | $abs(-1)$ | constant |
| Initial value of parameter P3 | $abs(1)$ | constant |
| Initial value of parameter P4 | $acos(-1)$ | constant |
| Initial value of parameter P5 | $acos(0.5)$ | constant |
| Initial value of parameter P6 | $asin(1)$ | constant |
| Initial value of parameter P7 | $asin(-0.5)$ | constant |
| Initial value of parameter P8 | $atan(2.8)$ | constant |
| Initial value of parameter P9 | $atan(-7.09)$ | constant |
| Initial value of parameter P10 | $ceil(0.5)$ | constant |
| Initial value of parameter P11 | $ceil(3.55)$ | constant |
| Initial value of parameter P12 | $ceil(-4.6)$ | constant |
| Initial value of parameter P13 | $cos(9.1)$ | constant |
| Initial value of parameter P14 | $cos(-0.22)$ | constant |
| Initial value of parameter P15 | $exp(0)$ | constant |
| Initial value of parameter P16 | $exp(1)$ | constant |
| Initial value of parameter P17 | $exp(0.77)$ | constant |
| Initial value of parameter P18 | $floor(-4.6)$ | constant |
| Initial value of parameter P19 | $floor(9.1)$ | constant |
| Initial value of parameter P20 | $log(0.2)$ | constant |
| Initial value of parameter P21 | $log(1)$ | constant |
| Initial value of parameter P22 | $log10(0.2)$ | constant |
| Initial value of parameter P23 | $log10(1)$ | constant |
| Initial value of parameter P24 | $pow(1, 2)$ | constant |
| Initial value of parameter P25 | $pow(2, 2)$ | constant |
| Initial value of parameter P26 | $pow(1.4, 5.1)$ | constant |
| Initial value of parameter P27 | $pow(4, 2)$ | constant |
| Initial value of parameter P28 | $pow(3.1, 2)$ | constant |
| Initial value of parameter P29 | $sqrt(4)$ | constant |
| Initial value of parameter P30 | $sqrt(7.4)$ | constant |
| Initial value of parameter P31 | $sin(2.1)$ | constant |
| Initial value of parameter P32 | $sin(0)$ | constant |
| Initial value of parameter P33 | $sin(-5.9)$ | constant |
| Initial value of parameter P34 | $tan(0)$ | constant |
| Initial value of parameter P35 | $tan(1.11)$ | constant |
| Initial value of parameter P36 | $tan(-6)$ | constant |
| Initial value of parameter P37 | $1 + 2$ | constant |
| Initial value of parameter P38 | $1 - 2$ | constant |
| Initial value of parameter P39 | $5 / 2$ | constant |
| Initial value of parameter P40 | $8 * 3$ | constant |]

Note: The test data for this model was generated from an analytical
solution of the system of equations.

*)
Previous version of this file:  

